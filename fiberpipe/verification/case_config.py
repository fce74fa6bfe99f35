"""The verification cases' configs: docs/verification.md, "each case is a config in configs/verify/".

Each case of :mod:`fiberpipe.verification.cases` and :mod:`~fiberpipe.verification.contact_cases`
reads its material, fiber radius, element length, fibers (straight polylines) and the scene values
it can (loads, damping, gravity, friction, plates, walls, drives, contact law, end time) from its
config through :func:`case_setup`; what a config cannot express (initial mode shapes or velocity
fields, pinned ends, quick-variant lengths) is added by the case and said in the config's header.
The references are computed from the same values, so the config is the source of truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config, load_config
from ..solver import Clamp, Clamps, LineLoad, Loads, Material, PointLoad, build_model

#: configs/verify of the source tree (tests monkeypatch it)
CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "verify"

#: case name (``python -m fiberpipe.verification CASE``) → its config in :data:`CONFIG_DIR`
CASE_CONFIGS = {
    "cantilever_small": "cantilever-small.yaml",
    "cantilever_large": "cantilever-large.yaml",
    "cantilever_frequency": "cantilever-frequency.yaml",
    "euler_buckling": "euler-buckling.yaml",
    "axial_wave_speed": "axial-wave-speed.yaml",
    "energy_drift": "energy-drift.yaml",
    "contact_parallel": "contact-parallel.yaml",
    "contact_crossed_2": "contact-crossed-2.yaml",
    "contact_crossed_6": "contact-crossed-6.yaml",
    "contact_crossed_10": "contact-crossed-10.yaml",
    "contact_crossed_90": "contact-crossed-90.yaml",
    "three_beam_static": "three-beam-static.yaml",
    "rearrangement": "study-rearrangement.yaml",
    "friction_inclined_stick": "friction-inclined-stick.yaml",
    "friction_inclined_slide": "friction-inclined-slide.yaml",
}


@dataclass
class CaseSetup:
    """A case's validated config and what the cases derive from it (SI)."""

    name: str
    path: Path
    cfg: Config

    # -- material and section -------------------------------------------------------------------
    @property
    def material(self) -> Material:
        from ..solver.build import material_from_config

        return material_from_config(self.cfg)

    @property
    def E(self) -> float:
        return float(self.cfg.material.youngs_modulus)

    @property
    def nu(self) -> float:
        return float(self.cfg.material.poisson_ratio_value)

    @property
    def rho(self) -> float:
        return float(self.cfg.material.density)

    def _required(self, value, key: str) -> float:
        if value is None:
            raise ValueError(f"{self.path}: the verification case needs {key}")
        return float(value)

    @property
    def r(self) -> float:
        return self._required(self.cfg.fiber.radius, "fiber.radius")

    @property
    def A(self) -> float:
        return math.pi * self.r**2

    @property
    def I(self) -> float:  # noqa: E743
        return math.pi * self.r**4 / 4

    @property
    def EI(self) -> float:
        return self.E * self.I

    @property
    def E_star(self) -> float:
        return self.E / (2 * (1 - self.nu**2))

    @property
    def element_length(self) -> float:
        return float(self.cfg.mesh.element_length)

    # -- geometry -------------------------------------------------------------------------------
    def fibers(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(start, end) of each fiber of ``input.polylines`` (m); every polyline must be straight."""
        out = []
        for k, pl in enumerate(self.cfg.input.polylines or []):
            p = np.asarray(pl, float)
            d = p[-1] - p[0]
            n = np.linalg.norm(d)
            off = np.linalg.norm(np.cross(p - p[0], d / n), axis=1) if n > 0 else np.array([np.inf])
            if not n > 0 or np.max(off) > 1e-9 * n:
                raise ValueError(f"{self.path}: input.polylines[{k}] must be a straight segment for this case")
            out.append((p[0], p[-1]))
        if not out:
            raise ValueError(f"{self.path}: the case needs input.polylines")
        return out

    def lengths(self) -> list[float]:
        return [float(np.linalg.norm(b - a)) for a, b in self.fibers()]

    def n_elements(self, length_m: float) -> int:
        return max(1, int(round(length_m / self.element_length)))

    def polys(self, length_m: float | None = None) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """(start, end, elements) per fiber; ``length_m`` shortens/lengthens every fiber from its start
        along its own direction (the quick/full variants of the 3-beam cases)."""
        out = []
        for a, b in self.fibers():
            if length_m is not None:
                b = a + (b - a) / np.linalg.norm(b - a) * length_m
            out.append((a, b, self.n_elements(float(np.linalg.norm(b - a)))))
        return out

    def model(self, length_m: float | None = None, nodes_m: np.ndarray | None = None):
        """The beam model of the config's fibers (straight, ``n_elements`` each), or of ``nodes_m``
        (same node count) for a perturbed geometry."""
        xs = []
        for a, b, n in self.polys(length_m):
            s = np.linspace(0.0, 1.0, n + 1)[:, None]
            xs.append(a + s * (b - a))
        off = np.cumsum([0] + [len(x) for x in xs])
        x = np.vstack(xs) if nodes_m is None else np.asarray(nodes_m, float)
        return build_model(x, off, self.r, self.material)

    # -- scene ----------------------------------------------------------------------------------
    def _scene(self, name: str):
        if name not in self.cfg.scene.effects:
            raise ValueError(f"{self.path}: the case needs scene.effects to list {name}")
        return getattr(self.cfg.scene, name)

    @property
    def damping_alpha(self) -> float:
        return float(self._scene("damping").alpha)

    @property
    def gravity(self) -> list[float]:
        return [float(g) for g in self._scene("gravity").acceleration]

    @property
    def mu(self) -> float:
        return float(self._scene("friction").mu)

    @property
    def end_time(self) -> float:
        return self._required(self.cfg.solver.end_time, "solver.end_time")

    @property
    def output_frames(self) -> int:
        return int(self.cfg.solver.output_frames)

    def settings(self, **overrides):
        """SimulationSettings from ``solver`` (dt_safety, end_time, output_frames), then ``overrides``."""
        from ..solver import SimulationSettings

        kw = {"dt_safety": float(self.cfg.solver.dt_safety), "output_frames": self.output_frames}
        if self.cfg.solver.end_time is not None:
            kw["end_time_s"] = float(self.cfg.solver.end_time)
        kw.update(overrides)
        return SimulationSettings(**kw)

    def clamps(self) -> Clamps:
        return Clamps([Clamp(c.fiber, c.at) for c in self._scene("clamps")])

    def loads(self, scale: float = 1.0) -> Loads:
        out = []
        for ld in self._scene("loads"):
            if ld.line_force is not None:
                out.append(LineLoad(ld.fiber, [scale * float(f) for f in ld.line_force]))
            else:
                out.append(PointLoad(ld.fiber, [scale * float(f) for f in ld.force], ld.at))
        return Loads(out)

    def load(self, k: int = 0):
        """The k-th ``scene.loads`` entry (config object: fiber, at, force, line_force)."""
        return self._scene("loads")[k]

    def law(self):
        """The contact law of ``scene.contact`` (Hertz laws: from the config's material)."""
        from fiberpipe.solver.laws import law_from_config

        contact = self._scene("contact")
        if not contact.law.startswith("hertz"):
            raise ValueError(f"{self.path}: the verification cases run Hertz laws, not {contact.law!r}")
        return law_from_config(contact, self.cfg.material)  # what a run of the config uses

    @property
    def plates(self):
        return self._scene("plates")

    @property
    def loading(self):
        return self.cfg.scene.loading

    @property
    def walls(self) -> dict:
        w = self._scene("walls")
        return {ax: tuple(float(v) for v in getattr(w, ax)) for ax in "xyz" if getattr(w, ax) is not None}

    def plane_penalty(self, kind: str) -> dict:
        """The config's plane penalty of ``kind`` ("plates" or "walls") as keyword arguments of
        :class:`~fiberpipe.solver.Plates` / :class:`~fiberpipe.solver.Walls`."""
        c = self._scene(kind)
        return {"penalty_factor": float(c.penalty_factor), "onset_fraction": float(c.onset_fraction)}

    @property
    def drives(self):
        return self._scene("drives")


def case_setup(name: str) -> CaseSetup:
    """Load and validate the config of case ``name`` (:data:`CASE_CONFIGS`) from :data:`CONFIG_DIR`."""
    try:
        path = Path(CONFIG_DIR) / CASE_CONFIGS[name]
    except KeyError:
        raise ValueError(f"no config for verification case {name!r}") from None
    if not path.exists():
        raise FileNotFoundError(f"verification case {name!r}: its config {path} does not exist "
                                "(the verification cases run from a source checkout with configs/verify/)")
    return CaseSetup(name, path, load_config(path))


def contact_hook(model, **overrides):
    """:func:`fiberpipe.solver.terms.contact.make_contact_hook` with the config schema's defaults
    (``scene.contact`` and ``scene.friction`` as a config that lists them without a block would
    have them) for what ``overrides`` does not set; the default law is for the model's material."""
    from types import SimpleNamespace

    from ..config import ContactConfig, FrictionConfig
    from ..solver.terms.contact import make_contact_hook
    from ..solver.laws import law_from_config

    if "law" not in overrides:
        mat = SimpleNamespace(youngs_modulus=model.material.youngs_modulus_pa, poisson_ratio_value=model.material.nu)
        overrides["law"] = law_from_config(ContactConfig(), mat)
    cc = ContactConfig()
    overrides.setdefault("mu", FrictionConfig().mu)
    overrides.setdefault("overlap_release_s", cc.overlap_release)
    overrides.setdefault("onset_m", float(cc.onset))
    overrides.setdefault("n_gauss", int(cc.gauss_points))
    return make_contact_hook(model, **overrides)
