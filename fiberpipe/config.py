"""YAML configs: loading, ``extends:``, unit conversion and validation (docs/config.md).

# Strategy: read the YAML (and, recursively, the file it ``extends:``), resolve relative paths
# against the folder of the file that names them, deep-merge the variant over its base, then
# validate the whole tree with pydantic models that forbid unknown keys. Quantities accept bare
# SI numbers or unit strings ("0.5 mm", "15 GPa", "1000 mm/min") and are stored as SI floats,
# so everything after :func:`load_config` is SI. Every failure becomes one :class:`ConfigError`
# line naming the file and the dotted key, with a close-match suggestion for misspelt keys.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from fiberpipe.errors import ConfigError
from fiberpipe.units import to_si

# ----------------------------------------------------------------------------------------------
# Quantity types


def _quantity(dimension: str):
    def convert(value):
        if value is None:
            return None
        return to_si(value, dimension)

    convert.dimension = dimension
    return BeforeValidator(convert)


def _vector(dimension: str, size: int = 3):
    def convert(value):
        if value is None:
            return None
        if not isinstance(value, (list, tuple)) or len(value) != size:
            raise ValueError(f"expected a list of {size} {dimension} values, got {value!r}")
        return [to_si(v, dimension) for v in value]

    convert.dimension = f"[3 × {dimension}]"
    return BeforeValidator(convert)


Length = Annotated[float, _quantity("length")]
Time = Annotated[float, _quantity("time")]
Rate = Annotated[float, _quantity("rate")]
Velocity = Annotated[float, _quantity("velocity")]
Pressure = Annotated[float, _quantity("pressure")]
Density = Annotated[float, _quantity("density")]
Angle = Annotated[float, _quantity("angle")]
Acceleration3 = Annotated[list[float], _vector("acceleration")]
Force3 = Annotated[list[float], _vector("force")]
LineForce3 = Annotated[list[float], _vector("line_force")]
Length3 = Annotated[list[float], _vector("length")]
Stiffness = Annotated[float, _quantity("stiffness")]


class Section(BaseModel):
    """Base of every config section: unknown keys are errors, values are validated on assignment."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)


def _positive(name: str, value: Optional[float]) -> Optional[float]:
    if value is not None and not (value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be positive and finite, got {value}")
    return value


# ----------------------------------------------------------------------------------------------
# input


class PhantomConfig(Section):
    """Synthetic volume of curved, touching fibers (``input.phantom``)."""

    n_fibers: int = Field(16, ge=1, le=5000)
    shape: list[int] = Field(default_factory=lambda: [150, 64, 64], description="z y x, voxels")
    radius_vox: float = Field(4.0, gt=0.5)
    voxel_size: Length = 62.5e-6
    touching_fraction: float = Field(1 / 3, ge=0, le=1)
    contrast_to_noise: float = Field(5.0, gt=0)
    blur_sigma_vox: float = Field(1.0, ge=0)
    seed: int = 0

    @field_validator("shape")
    @classmethod
    def _shape(cls, v):
        if len(v) != 3 or min(v) < 8:
            raise ValueError(f"shape must be 3 sizes (z y x) of at least 8 voxels, got {v}")
        return v

    @model_validator(mode="after")
    def _fibers_fit(self):
        from fiberpipe.imaging.phantom import min_cross_section_vox  # lazy: config loads without imaging

        need = min_cross_section_vox(self.radius_vox)
        if min(self.shape[1], self.shape[2]) < need:
            raise ValueError(
                f"input.phantom.radius_vox = {self.radius_vox:g} voxels does not fit input.phantom.shape (y and x "
                f"need at least {need} voxels: the diameter plus a margin; got shape {self.shape}, z y x): enlarge "
                f"the shape or lower radius_vox to at most {(min(self.shape[1:]) - 3) / 2:g}")
        return self


class InputConfig(Section):
    """What the run starts from: a volume file, a phantom, a fibers artifact or inline polylines."""

    volume: Optional[str] = None
    voxel_size: Optional[Length] = None
    dataset: Optional[str] = None
    shape: Optional[list[int]] = None
    dtype: Optional[str] = None
    phantom: Optional[PhantomConfig] = None
    fibers: Optional[str] = None
    polylines: Optional[list[list[Length3]]] = None
    truth: Optional[str] = None

    @model_validator(mode="after")
    def _one_source(self):
        given = [k for k in ("volume", "phantom", "fibers", "polylines") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of input.volume, input.phantom, input.fibers, input.polylines"
                + (f" (got {', '.join(given)})" if given else "")
            )
        _positive("input.voxel_size", self.voxel_size)
        if self.polylines is not None:
            for i, line in enumerate(self.polylines):
                if len(line) < 2:
                    raise ValueError(f"input.polylines[{i}] needs at least 2 points")
                if all(p == line[0] for p in line[1:]):
                    raise ValueError(f"input.polylines[{i}] has zero length (all its points coincide): remove it")
        return self

    @property
    def source(self) -> str:
        for k in ("volume", "phantom", "fibers", "polylines"):
            if getattr(self, k) is not None:
                return k
        raise AssertionError


# ----------------------------------------------------------------------------------------------
# imaging stages


class SegmentConfig(Section):
    method: Literal["otsu", "fixed"] = "otsu"
    threshold: Optional[float] = None
    smooth_sigma_vox: float = Field(1.0, ge=0)
    min_object_vox: int = Field(64, ge=0)
    fill_holes: bool = True

    @model_validator(mode="after")
    def _threshold(self):
        if self.method == "fixed" and self.threshold is None:
            raise ValueError("segment.method 'fixed' needs segment.threshold")
        return self


class SkeletonizeConfig(Section):
    enabled: Optional[bool] = Field(
        None, description="compute the skeleton (skeleton.h5); default: yes; false skips it when "
        "trace.method is slices, which does not read it"
    )


#: Defaults derived from the scan (``null`` in the schema): the study's mesh has elements of 0.3 mm on
#: fibers 0.5 mm across, 0.6 diameters per element, which the unset ``mesh.element_length`` keeps at
#: any scale.
ELEMENT_LENGTH_DIAMETERS = 0.6
#: The shortest traced piece counted as a fiber, in fiber diameters: the aspect ratio above 3:1 of
#: the WHO fiber counting rule (WHO 1997, phase-contrast membrane-filter method).
MIN_FIBER_LENGTH_DIAMETERS = 3.0
#: The largest node shift the mesh stage makes to resolve overlaps, in fiber radii: two diameters
#: (traced pieces that run into each other, as skeleton traces of a fiber mat do at crossings, are
#: pushed apart; more is a tracing error to look at).
MAX_OVERLAP_SHIFT_RADII = 4.0


def element_length_m(mesh: "MeshConfig", radius_m: float) -> float:
    """``mesh.element_length``, or :data:`ELEMENT_LENGTH_DIAMETERS` fiber diameters when unset
    (``radius_m``: ``fiber.radius`` or the fibers' median radius)."""
    if mesh.element_length is not None:
        return float(mesh.element_length)
    return ELEMENT_LENGTH_DIAMETERS * 2.0 * float(radius_m)


def max_overlap_shift_m(mesh: "MeshConfig", radius_m: float) -> float:
    """``mesh.max_overlap_shift``, or :data:`MAX_OVERLAP_SHIFT_RADII` fiber radii when unset."""
    if mesh.max_overlap_shift is not None:
        return float(mesh.max_overlap_shift)
    return MAX_OVERLAP_SHIFT_RADII * float(radius_m)


def min_fiber_length_m(trace: "TraceConfig", mesh: "MeshConfig", radius_m: float) -> float:
    """``trace.min_length``, or :data:`MIN_FIBER_LENGTH_DIAMETERS` fiber diameters when unset, and
    never below two mesh elements (the shortest fiber the mesh takes)."""
    if trace.min_length is not None:
        return float(trace.min_length)
    return max(MIN_FIBER_LENGTH_DIAMETERS * 2.0 * float(radius_m), 2.0 * element_length_m(mesh, radius_m))


class TraceConfig(Section):
    """Tracing options; ``None`` means the tracer's own default, scaled by the fiber radius."""

    method: Literal["auto", "slices", "dense", "skeleton"] = Field(
        "auto", description="auto: dense on a dense pack of thin fibers (mask volume fraction >= 0.35, radius <= 8 "
        "voxels) that is quasi-parallel or runs mostly along volume axes, else slices when the fibers are "
        "quasi-parallel (see min_aligned_fraction), else skeleton; dense: the slices tracer on the grey volume (read "
        "again) with the radius read from it")
    min_aligned_fraction: float = Field(0.9, ge=0, le=1, description="auto picks the slices tracer when at least this "
                                        "fraction of the fiber volume runs within 45 deg of one volume axis (mask "
                                        "structure tensor); slices below it warns")
    max_jump_vox: Optional[float] = Field(None, gt=0, description="slices: default max(2, 0.6 r)")
    max_skip: Optional[int] = Field(None, ge=0, description="slices: slices a track may miss (3)")
    min_length_vox: Optional[float] = Field(None, ge=0, description="default max(10, 3 r)")
    smooth_sigma_vox: Optional[float] = Field(None, ge=0, description="default max(1, r/2)")
    expected_radius: Optional[Length] = None
    min_length: Optional[Length] = Field(None, ge=0, description="shorter traced fibers are dropped, with a warning and a "
                                         "count in summary.json; default: derived from the scan, "
                                         f"{MIN_FIBER_LENGTH_DIAMETERS:g} fiber diameters (the traced fibers' median "
                                         "radius, or fiber.radius), and at least two mesh elements")
    join_gap_vox: Optional[float] = Field(None, ge=0, description="largest gap bridged between two pieces of one fiber "
                                          "(collinear, in line, similar radius); default max(4, 4 r); 0: no joining")
    pictures: bool = Field(True, description="write trace_slices.png, trace_midlines.png and orientation.png into the run folder")
    grey: bool = Field(False, description="slices: find fiber centres in the grey volume within the mask (dense packs, "
                       "whose mask merges touching fibers); the trace stage reads the input volume again")
    off_axis: Literal["trace", "drop"] = Field("trace", description="slices: regions (>= 2 % of the fiber volume) whose "
                                               "fibers run along another volume axis, such as a cross ply lying in the "
                                               "slices, are traced along their own axis, or left out (counted in "
                                               "summary.json, one warning line)")


def _memory(value):
    if value is None:
        return None
    from fiberpipe.units import to_bytes

    return to_bytes(value)


_memory.dimension = "memory (bytes)"
Memory = Annotated[float, BeforeValidator(_memory)]


def _on_off(value):
    # YAML 1.1 reads a bare on / off as a boolean
    return {True: "on", False: "off"}.get(value, value) if isinstance(value, bool) else value


class ChunksConfig(Section):
    """Volumes larger than memory: the segment, skeletonize and trace stages chunk by chunk
    (docs/imaging.md, "Volumes larger than memory")."""

    mode: Annotated[Literal["auto", "on", "off"], BeforeValidator(_on_off)] = Field(
        "auto", description="on: segment, skeletonize and trace read and write the volume slab by slab (input.volume "
        "in HDF5, Zarr, MetaImage, .npy or raw); off: in memory; auto: chunked when the volume's voxels × 16 bytes "
        "(the in-memory stages' working set) exceed memory_budget")
    memory_budget: Memory = Field(4e9, description="auto: the memory the in-memory stages may use, e.g. '4 GB', "
                                  "'16 GiB' (a bare number is bytes)")
    slices: int = Field(32, ge=1, description="slices per slab (segment, skeletonize) and per block (trace); "
                        "memory follows slices × Y × X")
    halo_vox: int = Field(32, ge=1, description="skeletonize: voxels read around each slab and tile, more than "
                          "the largest fiber radius")
    scheduler: Optional[str] = Field(None, exclude=True, description="address of a Dask scheduler: slabs and "
                                     "blocks run on its workers, which read the input files themselves "
                                     "(`--scheduler`); not part of the stages' cache keys")

    @field_validator("memory_budget")
    @classmethod
    def _budget(cls, v):
        return _positive("chunks.memory_budget", v)


class MeshConfig(Section):
    element_length: Optional[Length] = Field(
        None, description="beam element length; default: derived from the scan, "
        f"{ELEMENT_LENGTH_DIAMETERS:g} × the fiber diameter (fiber.radius, else the median radius of the fibers "
        "traced or read): 0.3 mm for the study's fibers 0.5 mm across")
    smooth_sigma: Length = 0.0
    resolve_overlaps: bool = Field(True, description="push apart fibers overlapping in the input (strain-free adjustment; the simulate stage also moves surfaces up to 5 % of r inside a plate or wall back out)")
    max_overlap_shift: Optional[Length] = Field(
        None, ge=0, description="refuse inputs whose overlaps need larger node shifts; default: derived from the "
        f"fiber radius, {MAX_OVERLAP_SHIFT_RADII:g} r (fiber.radius, else the fibers' median radius)")
    min_fiber_length: Optional[Length] = Field(None, ge=0, description="shorter fibers are dropped, with a warning and a count "
                                               "in summary.json; default: derived from the fiber radius as trace.min_length, "
                                               f"{MIN_FIBER_LENGTH_DIAMETERS:g} fiber diameters and at least two elements")

    @field_validator("element_length")
    @classmethod
    def _el(cls, v):
        return _positive("mesh.element_length", v)


class MaterialConfig(Section):
    youngs_modulus: Pressure = 15e9
    poisson_ratio: Optional[float] = None
    shear_modulus: Optional[Pressure] = None
    density: Density = 1380.0

    @model_validator(mode="after")
    def _check(self):
        _positive("material.youngs_modulus", self.youngs_modulus)
        _positive("material.density", self.density)
        if self.poisson_ratio is not None and self.shear_modulus is not None:
            raise ValueError("give material.poisson_ratio or material.shear_modulus, not both")
        if self.poisson_ratio is not None and not (-1 < self.poisson_ratio < 0.5):
            raise ValueError(f"material.poisson_ratio must be in (-1, 0.5), got {self.poisson_ratio}")
        _positive("material.shear_modulus", self.shear_modulus)
        return self

    @property
    def shear_modulus_pa(self) -> float:
        if self.shear_modulus is not None:
            return self.shear_modulus
        nu = 0.3 if self.poisson_ratio is None else self.poisson_ratio
        return self.youngs_modulus / (2 * (1 + nu))

    @property
    def poisson_ratio_value(self) -> float:
        if self.poisson_ratio is not None:
            return self.poisson_ratio
        if self.shear_modulus is not None:
            return self.youngs_modulus / (2 * self.shear_modulus) - 1
        return 0.3


class FiberConfig(Section):
    radius: Optional[Length] = None

    @field_validator("radius")
    @classmethod
    def _r(cls, v):
        return _positive("fiber.radius", v)


# ----------------------------------------------------------------------------------------------
# scene

EFFECTS = ("gravity", "damping", "contact", "friction", "plates", "walls", "clamps", "loads", "drives", "constraints")


def _registered_terms() -> dict:
    """The solver's term registry (``fiberpipe.solver.terms.TERMS``): the built-in terms and any term a
    program registered, whose config block this schema validates with the term's ``config_block``."""
    from fiberpipe.solver.terms import TERMS  # lazy: the config loads without the solver

    return TERMS


class GravityConfig(Section):
    acceleration: Acceleration3 = Field(default_factory=lambda: [0.0, 0.0, -9.81])


class DampingConfig(Section):
    alpha: Rate = 0.0
    beta: Time = 0.0

    @model_validator(mode="after")
    def _check(self):
        if self.alpha < 0 or self.beta < 0:
            raise ValueError("damping.alpha and damping.beta must be >= 0")
        return self


class ContactConfig(Section):
    law: str = Field("hertz_oriented", description="a registered contact law: linear | scaled_stiffness | "
                     "hertz_parallel | hertz_crossed | hertz_oriented (fiberpipe.solver.laws.LAWS)")
    stiffness: Optional[float] = Field(None, description="linear law: N/m² per unit length (N/m per contact)")
    preset: Optional[str] = None
    k_def: Optional[float] = None
    s0: Optional[float] = None
    s: Optional[float] = None
    d: Optional[Length] = None
    angle: Optional[Angle] = None
    skin: Optional[Length] = None
    overlap_release: Time = Field(
        1e-4, description="initial fiber–fiber overlaps (> 5 % of r) are released linearly over this time"
    )
    blend_length: Length = Field(
        5e-5, description="every law with a point part (all but hertz_parallel): straight length ℓ_blend available "
        "to a crossing's Hertz contact ellipse; the point law holds while its semi-major axis a ≤ ℓ_blend, the line "
        "law takes over by a = 2 ℓ_blend (a sixth of a 0.3 mm element: a crossing whose ellipse spans elements hops "
        "across joints and, as a point force, creates energy; docs/contact.md)"
    )
    formulation: Literal["potential"] = Field(
        "potential", description="normal contact kernel: 'potential' (the one there is) makes every force minus the "
        "gradient of one stored potential (Gauss points fixed on each segment with end weights, the angle blend "
        "with its derivatives; docs/contact.md)"
    )
    onset: Length = Field(
        0.0, description="penetration over which the fiber–fiber contact's force and stiffness rise from zero "
        "(0: the laws as they are)"
    )
    gauss_points: int = Field(
        2, description="Gauss points per segment of the line (parallel) part, 1…6"
    )

    @field_validator("law")
    @classmethod
    def _registered(cls, v):
        from fiberpipe.solver.laws import LAWS

        if v not in LAWS:
            close = difflib.get_close_matches(v, list(LAWS), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(f"{v!r} is not a contact law{hint}; choose from {sorted(LAWS)}")
        return v

    @model_validator(mode="after")
    def _check(self):
        from fiberpipe.solver.laws import LAWS

        LAWS[self.law].check_config(self)
        if self.stiffness is not None:
            _positive("contact.stiffness", self.stiffness)
        if self.angle is not None and not (0 <= self.angle <= math.pi / 2 + 1e-12):
            raise ValueError("contact.angle must be between 0 and 90 deg")
        _positive("contact.overlap_release", self.overlap_release)
        _positive("contact.blend_length", self.blend_length)
        if not (self.onset >= 0 and math.isfinite(self.onset)):
            raise ValueError(f"contact.onset must be >= 0, got {self.onset}")
        if "onset" in self.model_fields_set and self.formulation != "potential":
            raise ValueError("contact.onset applies to formulation 'potential' only")
        if not 1 <= self.gauss_points <= 6:
            raise ValueError(f"contact.gauss_points must be 1…6, got {self.gauss_points}")
        if "blend_length" in self.model_fields_set and self.law == "hertz_parallel":
            raise ValueError("contact.blend_length does not apply to law 'hertz_parallel' (it has no point part)")
        return self


class FrictionConfig(Section):
    mu: float = 0.2
    stiffness: Optional[Stiffness] = Field(None, description="tangential penalty k_t, N/m (default 0.02 m_min (2/Δt)²)")

    @field_validator("mu")
    @classmethod
    def _mu(cls, v):
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"friction.mu must be >= 0, got {v}")
        return v


PlateMode = Literal["moving", "fixed", "none"]


PENALTY_FACTOR_HELP = ("normal penalty of each node on the planes, k = factor × m (2/Δt)² with Δt the step in use "
                       "or 0.9 of the stable step, the larger (the larger of the plates' and walls' factors serves "
                       "every plane)")


ONSET_FRACTION_HELP = ("the plane penalty's force and stiffness rise from zero over a penetration of this fraction of "
                       "the fiber radius (0.02: 5 µm at r = 0.25 mm; the larger of the plates' and walls' serves every "
                       "plane); a shorter onset lets nodes that rattle on the planes gain energy at the default step, a "
                       "longer one leaves the fibers deeper in the planes (docs/contact.md)")


class PlatesConfig(Section):
    axis: Literal["x", "y", "z"] = "z"
    lower: PlateMode = "moving"
    upper: PlateMode = "fixed"
    lower_position: Optional[Length] = None
    upper_position: Optional[Length] = None
    penalty_factor: float = Field(0.1, gt=0, le=0.25, description=PENALTY_FACTOR_HELP)
    onset_fraction: float = Field(0.02, gt=0, le=0.5, description=ONSET_FRACTION_HELP)
    size: Optional[list[Length]] = Field(
        None, description="[length, width]: finite rectangular plates, their extents along the two axes of "
        "the plate plane in x, y, z order (axis y: along x, then z); a node whose centre lies outside the "
        "rectangle feels no plate (default: infinite plates); each at least a fiber diameter")
    centre: Optional[list[Length]] = Field(
        None, description="with `size`: the rectangle's centre in the plate plane, in the same order "
        "(default: the centre of the fibers' bounding box there)")

    @model_validator(mode="after")
    def _check_size(self):
        for key in ("size", "centre"):
            v = getattr(self, key)
            if v is not None and (len(v) != 2 or not all(math.isfinite(c) for c in v)):
                raise ValueError(f"scene.plates.{key} must be two finite lengths (along the plate plane's two "
                                 f"axes in x, y, z order), got {v}")
        if self.size is not None and not all(c > 0 for c in self.size):
            raise ValueError(f"scene.plates.size must be > 0 along both axes, got {self.size}")
        if self.centre is not None and self.size is None:
            raise ValueError("scene.plates.centre places a finite plate: give scene.plates.size too")
        return self


class WallsConfig(Section):
    x: Optional[list[Length]] = None
    y: Optional[list[Length]] = None
    z: Optional[list[Length]] = None
    penalty_factor: float = Field(0.1, gt=0, le=0.25, description=PENALTY_FACTOR_HELP)
    onset_fraction: float = Field(0.02, gt=0, le=0.5, description=ONSET_FRACTION_HELP)
    mu: Optional[float] = Field(
        None, description="Coulomb coefficient of the walls' friction on the fibers, when scene.effects lists "
        "friction (default: scene.friction.mu); 0: frictionless walls")

    @model_validator(mode="after")
    def _check(self):
        if self.mu is not None and not (self.mu >= 0 and math.isfinite(self.mu)):
            raise ValueError(f"scene.walls.mu must be ≥ 0, got {self.mu}")
        for axis in "xyz":
            v = getattr(self, axis)
            if v is not None and (len(v) != 2 or not v[0] < v[1]):
                raise ValueError(f"walls.{axis} must be [lower, upper] with lower < upper, got {v}")
        return self


class LoadingConfig(Section):
    displacement: Length = 0.0
    velocity: Velocity = 1000e-3 / 60
    ramp: Literal["smooth", "linear"] = "smooth"
    ramp_fraction: float = Field(
        0.1, gt=0, lt=0.5,
        description="smooth ramp: share of the loading time spent accelerating (and again decelerating); "
                    "the plateau speed is `velocity`, so the loading lasts U/v/(1 − ramp_fraction)")
    path: Optional[list[Length]] = Field(
        None, description="plate displacements reached in turn at `velocity` (a loading cycle, e.g. "
        "['1.0 mm', '0.4 mm', '1.15 mm']), each move with its own ramp; replaces `displacement`, "
        "which becomes the path's largest entry")
    hold: Time = Field(0.0, description="with `path`: the time the plates stand still at each turning point")

    @model_validator(mode="after")
    def _check(self):
        _positive("loading.velocity", self.velocity)
        if self.ramp == "linear" and "ramp_fraction" in self.model_fields_set:
            raise ValueError("loading.ramp_fraction applies to ramp: smooth only (a linear ramp starts "
                             "at full speed)")
        if self.path is not None:
            self._check_path()
        elif "hold" in self.model_fields_set and self.hold:
            raise ValueError("scene.loading.hold applies to a scene.loading.path (the holds at its turning "
                             "points); a single displacement has none")
        return self

    def _check_path(self) -> None:
        """The path's entries (≥ 0, the first > 0, no two in a row equal, a hold ≥ 0); ``displacement``
        becomes its largest entry."""
        if not self.path:
            raise ValueError("scene.loading.path is empty: give the plate displacements in turn, e.g. "
                             "['1 mm', '0.4 mm', '1.15 mm']")
        prev = 0.0
        for k, u in enumerate(self.path):
            if not (math.isfinite(u) and u >= 0):
                raise ValueError(f"scene.loading.path[{k}] = {u * 1e3:.4g} mm is below 0: the travel is "
                                 "measured from the plate's start towards the bundle")
            if u == prev:
                raise ValueError(f"scene.loading.path[{k}] = {u * 1e3:.4g} mm equals the entry before it "
                                 "(the start is 0): each entry moves the plate; use scene.loading.hold for a stop")
            prev = u
        if not (math.isfinite(self.hold) and self.hold >= 0):
            raise ValueError(f"scene.loading.hold must be ≥ 0, got {self.hold} s")
        far = max(self.path)
        if "displacement" in self.model_fields_set and self.displacement != far:
            raise ValueError(f"scene.loading.displacement ({self.displacement * 1e3:.4g} mm) and scene.loading.path "
                             "are both given: the path replaces the displacement; remove it or make it the path's "
                             f"largest entry ({far * 1e3:.4g} mm)")
        object.__setattr__(self, "displacement", far)


Anchor = Union[Literal["start", "end"], int]


class ConstraintsConfig(Section):
    lock_axial: Literal["all", "ends"] = Field(
        "all", description="the study's boundary condition (\"the movement is locked in the fiber orientation\"): "
        "the translation along `axis` of every node (all) or of each fiber's two end nodes (ends) is fixed at its "
        "initial value; rotations and the other translations stay free")
    axis: Literal["x", "y", "z"] = Field("z", description="the fibers' orientation (the bundle's axis)")


class ClampConfig(Section):
    fiber: int = Field(ge=0)
    at: Anchor = "start"


class LoadConfig(Section):
    fiber: int = Field(ge=0)
    at: Optional[Anchor] = None
    force: Optional[Force3] = None
    line_force: Optional[LineForce3] = None

    @model_validator(mode="after")
    def _check(self):
        if (self.force is None) == (self.line_force is None):
            raise ValueError("a load needs exactly one of force (with at) or line_force")
        if self.force is not None and self.at is None:
            raise ValueError("a point load needs 'at' (start, end or a node index)")
        return self


class DriveConfig(Section):
    fiber: int = Field(ge=0)
    displacement: Length3
    velocity: Velocity

    @model_validator(mode="after")
    def _check(self):
        _positive("drives.velocity", self.velocity)
        return self


class SceneConfig(Section):
    effects: list[str] = Field(
        default_factory=list, description="the terms the scene runs: gravity, damping, contact, friction, plates, "
        "walls, clamps, loads, drives, constraints, or the name of a term a program registered "
        "(fiberpipe.solver.register_term; its block is scene.<name>)")
    gravity: Optional[GravityConfig] = None
    damping: Optional[DampingConfig] = None
    contact: Optional[ContactConfig] = None
    friction: Optional[FrictionConfig] = None
    plates: Optional[PlatesConfig] = None
    walls: Optional[WallsConfig] = None
    loading: Optional[LoadingConfig] = None
    clamps: list[ClampConfig] = Field(default_factory=list)
    loads: list[LoadConfig] = Field(default_factory=list)
    drives: list[DriveConfig] = Field(default_factory=list)
    constraints: Optional[ConstraintsConfig] = None
    # the blocks of registered terms outside this schema (``scene.<name>``), validated by the term's
    # own ``config_block``; read them with :meth:`block`
    term_blocks: dict[str, Any] = Field(
        default_factory=dict, description="the blocks of registered terms, each validated by its term's own "
        "section; written as scene.<name> (they are collected here)")

    @model_validator(mode="before")
    @classmethod
    def _collect_term_blocks(cls, data):
        """``scene.<name>`` of a registered term the schema does not list goes to ``term_blocks``."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        terms = _registered_terms()
        blocks = dict(data.get("term_blocks") or {})
        for key in [k for k in data if k not in cls.model_fields and k in terms]:
            if getattr(terms[key], "config_block", None) is not None:
                blocks[key] = data.pop(key)
        if blocks:
            data["term_blocks"] = blocks
        return data

    @field_validator("effects")
    @classmethod
    def _known_effects(cls, v):
        terms = _registered_terms()
        for k, name in enumerate(v):
            if name not in EFFECTS and name not in terms:
                close = difflib.get_close_matches(name, list(terms), n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ValueError(f"scene.effects[{k}] = {name!r} is not a term{hint}; choose from {sorted(terms)}")
        return v

    def block(self, name: str):
        """The config block of term ``name``: a field of this schema, or a registered term's own block."""
        return getattr(self, name) if name in type(self).model_fields else self.term_blocks.get(name)

    @model_validator(mode="after")
    def _defaults_for_effects(self):
        if len(set(self.effects)) != len(self.effects):
            raise ValueError("scene.effects lists an effect twice")
        terms = _registered_terms()
        for name in set(self.term_blocks) | {n for n in self.effects if n not in EFFECTS}:
            block_cls = getattr(terms.get(name), "config_block", None)
            if block_cls is not None and not isinstance(self.term_blocks.get(name), block_cls):
                try:
                    self.term_blocks[name] = block_cls.model_validate(self.term_blocks.get(name) or {})
                except ValidationError as exc:
                    err = exc.errors()[0]
                    key = ".".join(["scene", name] + [str(p) for p in err["loc"]])
                    raise ValueError(f"{key}: {err['msg']}") from None
        # An effect listed without its block takes the block's defaults.
        defaults = {
            "gravity": GravityConfig,
            "damping": DampingConfig,
            "contact": ContactConfig,
            "friction": FrictionConfig,
            "plates": PlatesConfig,
            "walls": WallsConfig,
            "constraints": ConstraintsConfig,
        }
        for name, cls in defaults.items():
            if name in self.effects and getattr(self, name) is None:
                object.__setattr__(self, name, cls())
        # contact and friction run in one hook, which reads both blocks
        if "contact" in self.effects or "friction" in self.effects:
            for name in ("contact", "friction"):
                if getattr(self, name) is None:
                    object.__setattr__(self, name, defaults[name]())
        if "plates" in self.effects:
            self._check_plates()
        if "walls" in self.effects and all(getattr(self.walls, ax) is None for ax in "xyz"):
            raise ValueError("scene.effects lists walls but scene.walls gives no planes: add e.g. "
                             "scene.walls: {x: ['-1.5 mm', '1.5 mm']} or remove walls from scene.effects")
        for name in ("clamps", "loads", "drives"):
            if name in self.effects and not getattr(self, name):
                raise ValueError(f"scene.effects lists {name} but scene.{name} is empty")
        for k, d in enumerate(self.drives if "drives" in self.effects else []):
            if not any(d.displacement):
                raise ValueError(f"scene.drives[{k}].displacement is zero: the drive would not move fiber "
                                 f"{d.fiber}; give the displacement (e.g. [0, 0, '-0.3 mm'])")
        return self

    def _check_plates(self) -> None:
        """Requirements of ``plates`` that the config alone decides (the rest needs the mesh)."""
        p = self.plates
        moving = [k for k in ("lower", "upper") if getattr(p, k) == "moving"]
        if p.lower == "none" and p.upper == "none":
            raise ValueError("scene.plates.lower and scene.plates.upper are both none: no plate acts; set one "
                             "to fixed or moving, or remove plates from scene.effects")
        if moving and self.loading is None:
            raise ValueError(
                f"scene.plates.{moving[0]} is moving but there is no scene.loading to move it: add e.g. "
                "scene.loading: {displacement: '1 mm', velocity: '1000 mm/min'}, or make the plate fixed")
        if moving and not self.loading.displacement > 0:
            raise ValueError(
                f"scene.loading.displacement must be > 0 for the moving plate (scene.plates.{moving[0]}), "
                f"got {self.loading.displacement} m; give the plate's travel (e.g. '1 mm') or make it fixed")
        if self.loading is None:  # fixed plates: the loading's defaults are never used
            object.__setattr__(self, "loading", LoadingConfig())
        lo, hi = p.lower_position, p.upper_position
        if p.lower != "none" and p.upper != "none" and lo is not None and hi is not None and not lo < hi:
            raise ValueError(f"scene.plates.lower_position ({lo} m) must be below scene.plates.upper_position "
                             f"({hi} m): they are plane positions along {p.axis}")

    def warnings(self) -> list[str]:
        """Effects that are configured but cannot act, as messages for the user."""
        out = []
        if "friction" in self.effects and "contact" not in self.effects and "plates" not in self.effects and "walls" not in self.effects:
            out.append("scene.effects has friction but no contact, plates or walls: friction cannot act")
        for name in ("gravity", "damping", "contact", "friction", "plates", "walls", "constraints"):
            # contact and friction share one hook: listing either fills both blocks with their defaults
            given = name in self.model_fields_set
            if getattr(self, name) is not None and name not in self.effects and given:
                out.append(f"scene.{name} is configured but not listed in scene.effects: it is ignored")
        for name in ("clamps", "loads", "drives"):
            if getattr(self, name) and name not in self.effects:
                out.append(f"scene.{name} is configured but not listed in scene.effects: it is ignored")
        if "walls" in self.effects and self.walls.mu is not None and "friction" not in self.effects:
            out.append("scene.walls.mu is set but scene.effects lists no friction: the walls are frictionless")
        if "loading" in self.model_fields_set and not (
            "plates" in self.effects and "moving" in (self.plates.lower, self.plates.upper)
        ):
            out.append("scene.loading is configured but no plate is moving (scene.effects plates with "
                       "scene.plates lower or upper: moving): it is ignored")
        if "damping" in self.effects and self.damping.alpha == 0 and self.damping.beta == 0:
            out.append("scene.effects lists damping but scene.damping.alpha and beta are 0: nothing is damped")
        return out


class SolverConfig(Section):
    dt_safety: float = Field(0.9, description="the step as a fraction of the stable step (ω_max Δt = 2 dt_safety); "
                             "the plane penalties keep the stiffness of 0.9 below it, so a smaller value "
                             "resolves impacts on plates and walls better (undamped rattling scenes: 0.7, "
                             "docs/contact.md); the run warns once a contact law's slope (ωΔt)² passes "
                             "4 dt_safety², the same margin (docs/contact.md, a law that stiffens past the step)")
    dt: Optional[Time] = Field(None, description="fixed time step; default: the stable step × dt_safety")
    force_dt: bool = Field(False, description="run with solver.dt above the stable limit anyway (refused otherwise; "
                           "a run that blows up stops with its diagnosis and keeps its last good state)")
    end_time: Optional[Time] = None
    output_frames: int = Field(21, ge=2)
    history_every: Optional[int] = Field(None, ge=1)
    checkpoint_every: Optional[int] = Field(None, ge=1, description="steps between checkpoints")
    rotational_inertia_scaling: float = 1.0
    mass_scaling: float = 1.0
    threads: int = Field(1, ge=1, description="numba threads for the beam pass and the node update (4 prange tasks "
                         "of contiguous nodes) and for the potential contact pass's pairs (up to 8 tasks once 64 pairs are "
                         "within reach; the same forces bit for bit) and the fiber–fiber friction's pairs (up to 8 tasks of at "
                         "least 256 pairs in contact, once 512 are; the same forces bit for bit); the plane "
                         "friction stays serial; "
                         "> 1 uses a step loop of its own (with the built-in contact: compiled once and cached, ≈ 1 min); "
                         "pays on an idle machine with a core per thread (docs/benchmarks.md); numba runs at most "
                         "NUMBA_NUM_THREADS threads (read when it starts; fiberpipe study and fit set it to the largest "
                         "solver.threads of their runs unless it is set): a run asking for more warns")
    settle_time: Time = 0.0
    stable_step: Literal["element", "modes", "adaptive"] = Field(
        "element", description="the stable step dt_safety multiplies: element = the element-by-element bound "
        "(every element mode, the axial one included); modes = 2/ω_max of the assembled beam system with the "
        "scene's fixed degrees of freedom removed, × √(1 − plane penalty factor) (larger with "
        "scene.constraints.lock_axial: all); the fiber–fiber contact stiffness is not in it, dt_safety must "
        "cover it (paper-40: 0.85, 1.165 × fewer steps, load-cell curve within 0.08 % of the element step's; "
        "docs/benchmarks.md); adaptive = the element bound, each step split into as many equal sub-steps as the "
        "contact law's tangent at the current penetrations and the plane penalty need, with the same dt_safety "
        "margin, re-evaluated every 50 steps (deterministic: a resumed run is the same bit for bit; the "
        "sub-step of each history row in its dt_s; docs/solver.md)")

    @model_validator(mode="after")
    def _check(self):
        if not (0 < self.dt_safety <= 1):
            raise ValueError(f"solver.dt_safety must be in (0, 1], got {self.dt_safety}")
        _positive("solver.dt", self.dt)
        _positive("solver.end_time", self.end_time)
        if self.rotational_inertia_scaling < 1 or self.mass_scaling < 1:
            raise ValueError("solver.rotational_inertia_scaling and solver.mass_scaling must be >= 1")
        cores = usable_cores()
        if self.threads > cores:
            raise ValueError(f"solver.threads is {self.threads}, more than the {cores} cores this process may run on: "
                             "a thread without a core of its own makes the run slower, not faster")
        return self


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it, else ``os.cpu_count``)."""
    import os

    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


class ReferenceStageConfig(Section):
    displacement: Length = Field(description="the plate displacement U at which the stage was scanned")
    fibers: str = Field(description="the stage's scanned mid-lines (a fibers.h5)")


class PostConfig(Section):
    reference_fibers: Optional[str] = None
    plots: bool = True
    quasi_static_ratio: float = Field(1e-2, gt=0)
    reference_stages: list[ReferenceStageConfig] = Field(
        default_factory=list, description="scans at stages of the compaction: the position error of the "
        "simulated mid-lines at each stage's U (post/reference_stages.csv, .png)")


# ----------------------------------------------------------------------------------------------
# virtual specimens (``fiberpipe specimen``)


class SpecimenBowConfig(Section):
    spool_radius: Optional[Length] = Field(
        2 / (math.pi * 0.2445), description="every fiber a circular arc of this radius (the spool it came off); 2.604 m is the "
        "curvature (π/2)·0.2445 1/m whose random-plane projection matches the study's Table 4 read in 1/m")
    spool_radius_range: Optional[list[Length]] = Field(
        None, description="[lo, hi]: each fiber's radius drawn uniformly between them (a wound spool's layers); "
        "replaces spool_radius")
    plane: Literal["random", "flat", "upright"] = Field(
        "random", description="the bow's plane: random (stratified over 360°), flat (bow horizontal, in x-z) "
        "or upright (bow vertical, in y-z)")

    @model_validator(mode="after")
    def _check(self):
        r = self.spool_radius_range
        if r is not None:
            if len(r) != 2 or not 0 < r[0] < r[1]:
                raise ValueError(f"specimen.bow.spool_radius_range must be [lo, hi] with 0 < lo < hi, got {r}")
            object.__setattr__(self, "spool_radius", None)
        elif self.spool_radius is not None:
            _positive("specimen.bow.spool_radius", self.spool_radius)
        return self


class SpecimenWavinessConfig(Section):
    curvature_per_m: float = Field(0.0, ge=0, description="short-wave waviness: projected curvature (1/m) of "
                                   "a sum of sines added in x and in y; 0: none")
    wavelengths: list[Length] = Field(default_factory=lambda: [1.8e-3, 2.5e-3],
                                      description="[lo, hi] of the log-uniform wavelengths")
    modes: int = Field(2, ge=1, description="sines per component")

    @model_validator(mode="after")
    def _check(self):
        w = self.wavelengths
        if len(w) != 2 or not 0 < w[0] <= w[1]:
            raise ValueError(f"specimen.waviness.wavelengths must be [lo, hi] with 0 < lo <= hi, got {w}")
        return self


class SpecimenSettleConfig(Section):
    enabled: bool = Field(True, description="settle the deposited pile in the solver (gravity, friction, axial lock)")
    time: Time = Field(0.15, description="settling time")
    damping_alpha: Rate = 300.0
    mu: float = Field(0.2, ge=0)
    lock_axial: Literal["all", "ends", "none"] = "all"
    mass_scaling: float = Field(1.0, ge=1, description="solver.mass_scaling while settling (a larger step)")
    gravity_scale: float = Field(1.0, gt=0, description="gravity × this while settling (with mass_scaling: "
                                 "the same fall speed)")
    frames: int = Field(9, ge=2)
    contact: Optional[dict] = Field(
        None, description="the scene.contact section while settling and closing (e.g. {law: hertz_oriented}); "
        "none: the compaction's. Given, specimens compacted with different contact laws are the same specimens")


class SpecimenCloseConfig(Section):
    """``upper_plate: close``: the cassette closed onto the settled pile in the solver."""

    velocity: Velocity = Field(1000e-3 / 60, description="the upper plate's speed as it closes onto the pile "
                               "(smooth ramp)")
    relax_time: Time = Field(0.01, description="the plate held at the target height while the pile relaxes")
    damping_alpha: Rate = Field(1e5, description="mass damping while closing and relaxing (the study's "
                                "quasi-static α)")
    mass_scaling: float = Field(1.0, ge=1, description="solver.mass_scaling while closing (a larger step)")
    tolerance: Length = Field(25e-6, description="the closed pile's top may stand this far above the target height "
                              "(pressed into the plate's penalty by the closing load: 8 µm under 20 N for 40 fibers "
                              "of 15 mm); beyond it the target is refused as out of reach")
    frames: int = Field(5, ge=2)


class SpecimenWaveConfig(Section):
    span: Length = Field(2.5e-3, description="wavy_bundle: half-wavelength of each fiber's sinusoid (the span between "
                         "its crests and troughs, Gutowski's span)")
    rise: Length = Field(0.05e-3, description="wavy_bundle: peak-to-trough height of the sinusoid (Gutowski's rise; "
                         "β = span/rise)")

    @model_validator(mode="after")
    def _check(self):
        _positive("specimen.wave.span", self.span)
        _positive("specimen.wave.rise", self.rise)
        return self


class SpecimenYarnConfig(Section):
    """``kind: yarn``: fibers along z packed in an elliptical cross-section (x wide, y high) at the
    target v_f0, compacted between the plates along y (fiberpipe.model.specimen_yarn)."""

    aspect_ratio: float = Field(1.0, gt=0, le=20, description="the cross-section's width / height (x / y); "
                                "1: a circle")
    helix_angle: Optional[Angle] = Field(None, ge=0, lt=math.radians(60), description="twist: the helix angle "
                                         "of the fibers at the yarn's surface, tan α = 2π R T (R = √(a b)); "
                                         "none: twist_per_length")
    twist_per_length: float = Field(0.0, ge=0, description="twist T in turns per metre (used when helix_angle "
                                    "is none); 0: an untwisted yarn")
    orientation_spread: Angle = Field(0.0, ge=0, lt=math.radians(30), description="mean angle between "
                                      "neighbouring fibers Φ: each fiber tilted normal with σ = Φ/√π per component")
    wave_amplitude: Length = Field(0.0, ge=0, description="waviness: half the peak-to-trough lateral excursion of "
                                   "each fiber's sinusoid (random direction and phase); 0: straight fibers")
    wave_length: Length = Field(5e-3, description="waviness: the sinusoid's wavelength")
    walls: bool = Field(False, description="the cassette's walls at the cross-section's sides (x = ±a); false: "
                        "no walls (the yarn spreads freely between the plates)")
    overlap_tolerance: float = Field(0.01, gt=0, lt=0.5, description="largest fiber–fiber overlap left by the "
                                     "packing, as a fraction of the radius (2r − d ≤ this × r); beyond it the "
                                     "v_f0 is refused as not packable")

    @model_validator(mode="after")
    def _check(self):
        _positive("specimen.yarn.wave_length", self.wave_length)
        return self


class SpecimenConfig(Section):
    """A virtual specimen: ``n_fibers`` fibers of ``fiber.radius`` deposited in a cassette."""

    kind: Literal["cassette", "network_3d", "planar_mat", "wavy_bundle", "yarn"] = Field(
        "cassette", description="cassette: quasi-parallel fibers deposited and settled in the cassette (below); "
        "network_3d: straight fibers of isotropic orientation, planar_mat: straight fibers in random horizontal "
        "directions, wavy_bundle: aligned sinusoidal fibers (specimen.wave), each placed at random without overlap in "
        "a cell of width × depth at the target v_f0; yarn: aligned fibers packed in an elliptical cross-section at "
        "the target v_f0 with optional twist, orientation spread and waviness (specimen.yarn; docs/specimen.md)")
    seed: int = 0
    seeds: Optional[list[int]] = Field(
        None, description="an ensemble: one specimen per seed, each built and compacted (fiberpipe run, study "
        "and fit report F(U) as the seeds' mean with a band); none: the one specimen of seed")
    n_fibers: int = Field(40, ge=1, le=100000)
    length: Length = 15e-3
    width: Length = 3e-3
    volume_fraction: float = Field(0.377, gt=0, lt=0.9069,
                                   description="target v_f0: sets the cassette height (the plate gap)")
    upper_plate: Literal["target", "pile", "close"] = Field(
        "target", description="target: the upper plate at the height of the target v_f0 (the pile must fit "
        "under it); pile: on the settled pile's top (v_f0 follows the pile); close: the upper plate closes "
        "from the settled pile's top down to the target v_f0's height in the solver and holds there while the "
        "pile relaxes (specimen.close); its end state is the specimen")
    points_per_fiber: int = Field(61, ge=3)
    phi_mean: Angle = Field(math.radians(6.0), ge=0, description="mean angle between neighbouring fibers (the Φ "
                            "spread): tilts normal with σ = phi_mean/√π per component")
    y_tilt_scale: float = Field(1.0, gt=0, description="vertical tilt drawn for the drop, × σ")
    candidates: int = Field(2, ge=1, description="trial drops per fiber, the lowest kept (denser piles)")
    gap: Length = Field(1e-6, description="contact clearance in the pile")
    strain: Optional[float] = Field(
        None, gt=0, lt=1, description="nominal compaction strain U/h0 of the ready config: its "
        "scene.loading.displacement becomes strain × the plate gap (none: the base config's displacement)")
    depth: Optional[Length] = Field(None, description="network_3d, planar_mat, wavy_bundle: the cell's size along z "
                                    "(walls at 0 and depth; default: the width)")
    wave: SpecimenWaveConfig = Field(default_factory=SpecimenWaveConfig)
    yarn: SpecimenYarnConfig = Field(default_factory=SpecimenYarnConfig)
    bow: SpecimenBowConfig = Field(default_factory=SpecimenBowConfig)
    waviness: SpecimenWavinessConfig = Field(default_factory=SpecimenWavinessConfig)
    settle: SpecimenSettleConfig = Field(default_factory=SpecimenSettleConfig)
    close: SpecimenCloseConfig = Field(default_factory=SpecimenCloseConfig)

    @model_validator(mode="after")
    def _check(self):
        _positive("specimen.length", self.length)
        _positive("specimen.width", self.width)
        _positive("specimen.gap", self.gap)
        if self.seeds is not None:
            check_seeds(self.seeds, "specimen.seeds")
        return self


def check_seeds(seeds: list[int], key: str) -> None:
    """An ensemble's seeds: at least one, none twice, none negative (``key`` names them in the error)."""
    if not seeds:
        raise ValueError(f"{key} is empty: give at least one seed (e.g. [0, 1, 2, 3])")
    twice = sorted({s for s in seeds if seeds.count(s) > 1})
    if twice:
        raise ValueError(f"{key} gives seed {twice[0]} more than once: each seed is one specimen")
    if min(seeds) < 0:
        raise ValueError(f"{key}: seeds must be >= 0, got {min(seeds)}")


class Config(Section):
    """A whole fiberpipe config (docs/config.md). All quantities are SI floats."""

    name: str = "run"
    input: InputConfig
    segment: SegmentConfig = Field(default_factory=SegmentConfig)
    skeletonize: SkeletonizeConfig = Field(default_factory=SkeletonizeConfig)
    trace: TraceConfig = Field(default_factory=TraceConfig)
    chunks: ChunksConfig = Field(default_factory=ChunksConfig)
    mesh: MeshConfig = Field(default_factory=MeshConfig)
    material: MaterialConfig = Field(default_factory=MaterialConfig)
    fiber: FiberConfig = Field(default_factory=FiberConfig)
    scene: SceneConfig = Field(default_factory=SceneConfig)
    solver: SolverConfig = Field(default_factory=SolverConfig)
    post: PostConfig = Field(default_factory=PostConfig)
    specimen: Optional[SpecimenConfig] = None

    # Where the config came from, for messages and relative paths (not part of the YAML).
    source_path: Optional[str] = Field(None, exclude=True)

    @model_validator(mode="after")
    def _skeleton_for_the_skeleton_tracer(self):
        if self.trace.method == "skeleton" and self.skeletonize.enabled is False:
            raise ValueError(
                "skeletonize.enabled is false but trace.method is skeleton, which traces the skeleton: "
                "remove skeletonize.enabled (or set it true), or use trace.method: slices")
        return self

    @model_validator(mode="after")
    def _element_length_from_fiber_radius(self):
        # the derived default, resolved now where the radius is known (fiber.radius); else the mesh and
        # trace stages derive it from the radius of the fibers they read
        if self.mesh.element_length is None and self.fiber.radius is not None:
            self.mesh.element_length = element_length_m(self.mesh, self.fiber.radius)
        return self

    @model_validator(mode="after")
    def _scene_indices(self):
        if self.input.polylines is not None:  # the fibers are known now: check the indices the scene uses
            n = len(self.input.polylines)
            for name in ("clamps", "loads", "drives"):
                if name not in self.scene.effects:
                    continue
                for k, item in enumerate(getattr(self.scene, name)):
                    if item.fiber >= n:
                        raise ValueError(
                            f"scene.{name}[{k}].fiber = {item.fiber}: input.polylines has {n} fiber"
                            f"{'s' if n != 1 else ''} (indices 0..{n - 1})")
        return self

    def section_sha256(self, *names: str) -> str:
        """Content hash of the validated (SI) sections ``names``, for stage cache keys."""
        data = {n: getattr(self, n).model_dump(mode="json") for n in names}
        blob = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()

    def sha256(self) -> str:
        blob = json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()


# ----------------------------------------------------------------------------------------------
# Loading

#: Dotted keys whose values are paths, resolved against the folder of the file that sets them.
PATH_KEYS = (("input", "volume"), ("input", "fibers"), ("input", "truth"), ("post", "reference_fibers"))


class _DuplicateKey(yaml.YAMLError):
    """A mapping that names the same key twice (YAML forbids it; PyYAML keeps the last silently)."""

    def __init__(self, key, line: int, first_line: int):
        self.key, self.line, self.first_line = key, line, first_line
        super().__init__(f"duplicate key {key!r} at line {line}")


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (merge keys ``<<`` may
    still be overridden, as YAML intends)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    if key in seen:
                        raise _DuplicateKey(key, key_node.start_mark.line + 1, seen[key])
                    seen[key] = key_node.start_mark.line + 1
                except TypeError:  # unhashable key: SafeLoader reports it itself
                    continue
        return super().construct_mapping(node, deep=deep)


def _read_yaml(path: Path) -> dict:
    if not path.exists():
        raise ConfigError("config file not found", where=str(path))
    if path.is_dir():
        raise ConfigError("is a folder, not a config file", where=str(path))
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ConfigError("is not a text (YAML) file", where=str(path)) from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)
    except _DuplicateKey as exc:
        raise ConfigError(
            f"duplicate key '{exc.key}' at line {exc.line} of {path} (first given at line {exc.first_line}); "
            "keep only one"
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise ConfigError(f"is not valid YAML{line}: {problem}", where=str(path)) from None
    if data is None:
        raise ConfigError("is empty", where=str(path))
    if not isinstance(data, dict):
        raise ConfigError("must be a YAML mapping of sections (name, input, scene, ...)", where=str(path))
    return data


def _resolve_paths(data: dict, folder: Path) -> None:
    for section, key in PATH_KEYS:
        sec = data.get(section)
        if isinstance(sec, dict) and isinstance(sec.get(key), str):
            p = Path(sec[key]).expanduser()
            if not p.is_absolute():
                sec[key] = str((folder / p).resolve())
    stages = data.get("post", {}).get("reference_stages") if isinstance(data.get("post"), dict) else None
    for stage in stages if isinstance(stages, list) else []:  # post.reference_stages[*].fibers
        if isinstance(stage, dict) and isinstance(stage.get("fibers"), str) and not Path(stage["fibers"]).expanduser().is_absolute():
            stage["fibers"] = str((folder / Path(stage["fibers"]).expanduser()).resolve())


def _deep_merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = v
    return out


def load_raw(path: str | Path, _seen: tuple = ()) -> dict:
    """Read a config file and the chain of files it ``extends:``, merged, paths resolved."""
    path = Path(path).resolve()
    if path in _seen:
        raise ConfigError("extends: forms a cycle", where=str(path))
    data = _read_yaml(path)
    _resolve_paths(data, path.parent)
    base = data.pop("extends", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError("extends: must be the path of another config file", where=str(path))
    base_path = (path.parent / base).resolve()
    if not base_path.exists():
        raise ConfigError(f"extends: {base} not found", where=str(path))
    return _deep_merge(load_raw(base_path, _seen + (path,)), data)


def _model_at(model: type[BaseModel], loc: tuple) -> Optional[type[BaseModel]]:
    """The pydantic model class that owns the field at ``loc`` (for key suggestions)."""
    current: Any = model
    for part in loc:
        if isinstance(part, int) or current is None:
            continue
        fields = getattr(current, "model_fields", None)
        if not fields or part not in fields:
            return current if fields else None
        ann = fields[part].annotation
        current = _unwrap_model(ann)
    return current


def _unwrap_model(ann) -> Optional[type[BaseModel]]:
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    for arg in getattr(ann, "__args__", ()) or ():
        found = _unwrap_model(arg)
        if found is not None:
            return found
    return None


def _format_error(err: dict, where: str) -> str:
    loc = tuple(err["loc"])
    # Drop pydantic's tagged-union and validator markers from the dotted key.
    parts = [str(p) if not isinstance(p, int) else f"[{p}]" for p in loc if not str(p).startswith("function-")]
    key = ".".join(parts).replace(".[", "[")
    kind = err["type"]
    if kind == "extra_forbidden":
        owner = _model_at(Config, loc[:-1])
        name = str(loc[-1])
        hint = ""
        if owner is not None:
            close = difflib.get_close_matches(name, list(owner.model_fields), n=1, cutoff=0.6)
            if close:
                hint = f" (did you mean '{close[0]}'?)"
            else:
                hint = f" (known keys: {', '.join(k for k in owner.model_fields if k != 'source_path')})"
        return f"unknown key '{key}'{hint}"
    if kind == "missing":
        return f"missing required key '{key}'"
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    if kind == "literal_error":
        return f"'{key}': {msg}, got {err.get('input')!r}"
    if not key or msg.startswith(f"{key}.") or msg.startswith(f"{key} "):
        return msg  # the message names its key itself
    return f"'{key}': {msg}"


def validate_config(data: dict, *, where: str = "<config>") -> Config:
    """Validate a merged config mapping; raise :class:`ConfigError` naming the first bad key."""
    try:
        cfg = Config.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        first = _format_error(errors[0], where)
        more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
        raise ConfigError(first + more, where=where) from None
    cfg.source_path = where
    return cfg


def load_config(path: str | Path, overrides: Optional[dict] = None) -> Config:
    """Load, merge (``extends:``), apply dotted-key ``overrides`` and validate a config file.

    Parameters
    ----------
    path : str or Path
        The YAML file.
    overrides : dict, optional
        ``{"scene.damping.alpha": "1e4 1/s", ...}`` applied after merging (used by studies).
    """
    data = load_raw(path)
    for dotted, value in (overrides or {}).items():
        set_dotted(data, dotted, value)
    return validate_config(data, where=str(path))


def set_dotted(data: dict, dotted: str, value) -> None:
    """Set ``data[a][b]…`` for the dotted key ``a.b…`` (an integer part indexes a list), creating
    missing sections; a key that walks into a value or past a list's end is a ConfigError."""
    parts = dotted.split(".")
    cur: Any = data
    for i, p in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(cur, list):
            if not p.isdigit() or int(p) >= len(cur):
                held = f"0…{len(cur) - 1}" if cur else "it is empty"
                raise ConfigError(f"'{dotted}': '{'.'.join(parts[:i]) or p}' is a list of {len(cur)}; "
                                  f"'{p}' is not one of its indices ({held})")
            p = int(p)
        elif not isinstance(cur, dict):
            raise ConfigError(f"'{dotted}': '{'.'.join(parts[:i])}' is a value ({cur!r}), not a section")
        if last:
            cur[p] = value
        else:
            if isinstance(cur, dict) and cur.get(p) is None:
                cur[p] = [] if parts[i + 1].isdigit() else {}
            cur = cur[p]


def _type_name(ann) -> str:
    import typing

    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        for meta in args[1:]:
            dim = getattr(getattr(meta, "func", None), "dimension", None)
            if dim:
                from fiberpipe.units import SI_UNITS

                unit = SI_UNITS.get(dim.strip("[]3 × "), "")
                return f"{dim} ({unit})" if unit else dim
        return _type_name(args[0])
    if origin is typing.Union:
        names = [_type_name(a) for a in args if a is not type(None)]
        return " or ".join(names)
    if origin is typing.Literal:
        return " ∣ ".join(str(a) for a in args)
    if origin in (list, tuple):
        return f"list of {_type_name(args[0])}" if args else "list"
    return getattr(ann, "__name__", str(ann))


def reference_markdown() -> str:
    """A Markdown table of every config key, its type, default and description (docs/config.md)."""
    lines = ["| key | type (SI unit) | default | notes |", "| --- | --- | --- | --- |"]

    def walk(model: type[BaseModel], prefix: str):
        for name, f in model.model_fields.items():
            if name == "source_path":
                continue
            key = f"{prefix}{name}"
            sub = _unwrap_model(f.annotation)
            default = f.default if f.default_factory is None else f.default_factory()
            if isinstance(default, BaseModel):
                default = "(section)"
            if str(default) == "PydanticUndefined":
                default = "required"
            tname = _type_name(f.annotation)
            if f.metadata:  # pydantic moves Annotated metadata of plain fields here
                import typing

                tname = _type_name(typing.Annotated[(f.annotation, *f.metadata)])
            lines.append(f"| `{key}` | {tname} | {default} | {f.description or ''} |")
            if sub is not None and sub is not model:
                walk(sub, key + ".")

    walk(Config, "")
    return "\n".join(lines)
