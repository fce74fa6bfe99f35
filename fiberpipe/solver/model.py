"""Static beam model (rest geometry, section and material constants, lumped masses).

The :class:`Model` holds everything that does not change during a run, for all fibers in flat
arrays with CSR offsets (fiber ``i`` owns nodes ``node_offsets[i]:node_offsets[i+1]`` and the
elements joining consecutive nodes). SI units throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import FiberpipeError
from ._kernels_beam import element_rest_strains


@dataclass(frozen=True)
class Material:
    """Linear elastic isotropic material.

    Parameters
    ----------
    youngs_modulus_pa : float, Pa
    density_kg_m3 : float, kg/m³
    poisson_ratio : float, optional — used when ``shear_modulus_pa`` is not given (G = E/2(1+ν)).
    shear_modulus_pa : float, optional, Pa
    """

    youngs_modulus_pa: float
    density_kg_m3: float
    poisson_ratio: float | None = 0.3
    shear_modulus_pa: float | None = None

    def __post_init__(self):
        if not (self.youngs_modulus_pa > 0 and math.isfinite(self.youngs_modulus_pa)):
            raise FiberpipeError(f"youngs_modulus must be > 0, got {self.youngs_modulus_pa}", where="material")
        if not (self.density_kg_m3 > 0 and math.isfinite(self.density_kg_m3)):
            raise FiberpipeError(f"density must be > 0, got {self.density_kg_m3}", where="material")
        if self.shear_modulus_pa is None:
            nu = self.poisson_ratio
            if nu is None or not (-1.0 < nu < 0.5):
                raise FiberpipeError(f"poisson_ratio must be in (-1, 0.5), got {nu}", where="material")
        elif not self.shear_modulus_pa > 0:
            raise FiberpipeError(f"shear_modulus must be > 0, got {self.shear_modulus_pa}", where="material")

    @property
    def G(self) -> float:
        """Shear modulus, Pa."""
        if self.shear_modulus_pa is not None:
            return float(self.shear_modulus_pa)
        return self.youngs_modulus_pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def nu(self) -> float:
        """Poisson ratio (from E and G when G is given)."""
        if self.shear_modulus_pa is not None:
            return self.youngs_modulus_pa / (2.0 * self.shear_modulus_pa) - 1.0
        return float(self.poisson_ratio)

    @property
    def shear_factor(self) -> float:
        """Cowper's shear correction factor of a solid circle, 6(1+ν)/(7+6ν) (Cowper, J. Appl. Mech. 33, 1966)."""
        nu = min(max(self.nu, -0.99), 0.49)
        return 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)

    @property
    def wave_speed_m_s(self) -> float:
        """Bar wave speed √(E/ρ), m/s."""
        return math.sqrt(self.youngs_modulus_pa / self.density_kg_m3)


def _frames_parallel_transport(nodes: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) of node frames of one fiber: d3 along the nodal tangent
    (central difference of the chords), d1 carried along by parallel transport (Bishop frame)."""
    n = nodes.shape[0]
    chords = np.diff(nodes, axis=0)
    chords /= np.linalg.norm(chords, axis=1)[:, None]
    t = np.empty((n, 3))
    t[0] = chords[0]
    t[-1] = chords[-1]
    if n > 2:
        s = chords[:-1] + chords[1:]
        nrm = np.linalg.norm(s, axis=1)
        bad = nrm < 1e-12
        s[bad] = chords[1:][bad]
        nrm[bad] = 1.0
        t[1:-1] = s / nrm[:, None]
    # first d1: perpendicular to t0, from the axis least aligned with it
    e = np.eye(3)[np.argmin(np.abs(t[0]))]
    d1 = e - t[0] * np.dot(e, t[0])
    d1 /= np.linalg.norm(d1)
    R = np.empty((n, 3, 3))
    for i in range(n):
        if i > 0:
            a, b = t[i - 1], t[i]
            c = np.cross(a, b)
            s = np.linalg.norm(c)
            co = np.dot(a, b)
            if s > 1e-14:
                k = c / s
                ang = math.atan2(s, co)
                d1 = d1 * math.cos(ang) + np.cross(k, d1) * math.sin(ang) + k * np.dot(k, d1) * (1 - math.cos(ang))
            d1 = d1 - b * np.dot(d1, b)
            d1 /= np.linalg.norm(d1)
        d3 = t[i]
        d2 = np.cross(d3, d1)
        R[i] = np.column_stack([d1, d2, d3])
    return matrices_to_quats(R)


def matrices_to_quats(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) of rotation matrices (n, 3, 3) (Shepperd's method)."""
    n = R.shape[0]
    q = np.empty((n, 4))
    for i in range(n):
        m = R[i]
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        if tr > 0:
            s = math.sqrt(tr + 1.0) * 2
            q[i] = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
            s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
            q[i] = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif m[1, 1] > m[2, 2]:
            s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
            q[i] = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
        else:
            s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
            q[i] = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q /= np.linalg.norm(q, axis=1)[:, None]
    return q


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - w * z)
    R[:, 0, 2] = 2 * (x * z + w * y)
    R[:, 1, 0] = 2 * (x * y + w * z)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - w * x)
    R[:, 2, 0] = 2 * (x * z - w * y)
    R[:, 2, 1] = 2 * (y * z + w * x)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


@dataclass
class Model:
    """Static data of a beam model, all fibers in flat arrays.

    Attributes (N nodes, E elements, F fibers; SI units)
    ----------
    nodes_m : (N, 3) rest positions, m.  quats0 : (N, 4) rest node frames (w, x, y, z).
    node_offsets : (F+1,) int64 CSR offsets of fibers into nodes.
    node_fiber : (N,) int64 fiber of each node.
    el_n1 : (E,) int64 first node of each element (second = el_n1 + 1).
    el_fiber : (E,) int64.  el_L0 : (E,) rest lengths, m.  el_invL0 : (E,) 1/m.
    el_radius : (E,) m.  el_C : (E, 3) (k_s G A, k_s G A, E A), N.
    el_D : (E, 3) (E I, E I, G J), N·m².  el_Dk : (E, 3) el_D / L0, N·m.
    gamma_rest, theta_rest : (E, 3) rest strains (stress-free traced geometry).
    mass : (N,) lumped translational mass ρ A L/2 from each adjacent element, kg.
    J : (N, 3) lumped rotary inertia in the node frame, isotropic: ρ J_p L/2 × s on all three axes
        (J_p = 2I, the polar moment), kg·m² (see :func:`build_model`).
    radius_node : (N,) m (mean of the adjacent elements).
    material : Material.  rotary_inertia_scale : s (1 = physical).
    """

    nodes_m: np.ndarray
    quats0: np.ndarray
    node_offsets: np.ndarray
    node_fiber: np.ndarray
    el_n1: np.ndarray
    el_fiber: np.ndarray
    el_L0: np.ndarray
    el_invL0: np.ndarray
    el_radius: np.ndarray
    el_C: np.ndarray
    el_D: np.ndarray
    el_Dk: np.ndarray
    gamma_rest: np.ndarray
    theta_rest: np.ndarray
    mass: np.ndarray
    J: np.ndarray
    radius_node: np.ndarray
    material: Material
    rotary_inertia_scale: float = 1.0
    mass_scale: float = 1.0
    inv_mass: np.ndarray = field(init=False, repr=False)
    inv_J: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.inv_mass = 1.0 / self.mass
        self.inv_J = 1.0 / self.J

    @property
    def n_nodes(self) -> int:
        return int(self.nodes_m.shape[0])

    @property
    def n_elements(self) -> int:
        return int(self.el_n1.shape[0])

    @property
    def n_fibers(self) -> int:
        return int(self.node_offsets.shape[0] - 1)

    def fiber_nodes(self, i: int) -> slice:
        """Slice of the nodes of fiber ``i``."""
        return slice(int(self.node_offsets[i]), int(self.node_offsets[i + 1]))

    def fiber_node_index(self, fiber: int, at) -> int:
        """Global node index of ``at`` (``"start"``, ``"end"`` or a local node index, negative from the end)."""
        if not 0 <= fiber < self.n_fibers:
            raise FiberpipeError(f"fiber {fiber} does not exist (the model has {self.n_fibers} fibers)")
        a, b = int(self.node_offsets[fiber]), int(self.node_offsets[fiber + 1])
        if at == "start":
            return a
        if at == "end":
            return b - 1
        try:
            k = int(at)
        except (TypeError, ValueError):
            raise FiberpipeError(f"'at' must be start, end or a node index, got {at!r}") from None
        if k < 0:
            k += b - a
        if not 0 <= k < b - a:
            raise FiberpipeError(f"node {at} is out of range for fiber {fiber} ({b - a} nodes)")
        return a + k


def build_model(nodes_m, node_offsets, radius_m, material: Material, *,
                rotary_inertia_scale: float = 1.0, mass_scale: float = 1.0) -> Model:
    """Build a :class:`Model` from plain arrays; the given geometry is the stress-free rest state.

    Parameters
    ----------
    nodes_m : (N, 3) array_like, m — node positions, fibers one after the other.
    node_offsets : (F+1,) array_like int — fiber i owns ``nodes_m[node_offsets[i]:node_offsets[i+1]]``.
    radius_m : float or (F,) array_like, m — fiber radius.
    material : Material
    rotary_inertia_scale : float — multiplies the lumped rotary inertia (1 = physical; > 1 is the
        LS-DYNA/Abaqus rotary-inertia scaling: it lowers the rotation-dominated frequencies at the
        cost of wrong high-frequency rotational dynamics).
    mass_scale : float — multiplies all inertia (mass scaling: Δt grows as √mass_scale; gravity
        still acts on the physical mass).

    Notes
    -----
    The lumped rotary inertia is isotropic, ``ρ J_p L/2`` about every axis (the polar value, twice
    the bending one; Abaqus offers the same choice as ``ROTARY INERTIA=ISOTROPIC`` for Timoshenko
    beams). With the exact, anisotropic ``(ρIL/2, ρIL/2, ρJ_pL/2)`` Euler's equations carry the
    gyroscopic term ``Ω × JΩ``, which an explicit step can only take at the old angular velocity;
    near the stability limit that coupling of the bending-rotation modes is unstable: a free 3 mm
    fiber spinning at 1e4 rad/s about its axis (a torsional vibration of 0.1 mrad at the element
    frequency does that) gained 1000× its energy in 12 000 steps, at 1e5 rad/s it blew up in 1 600
    (tests/solver/test_rotary_inertia.py). With isotropic inertia ``Ω × JΩ = 0`` exactly, the
    rotation update is the exact exponential map of a torque-free spin, and energy is conserved
    (1.4e-5 over 1.1e5 steps at 1e5 rad/s). The price is a doubled rotary inertia in bending, a
    correction of order (r/λ)² to bending waves of wavelength λ (below 1e-4 for the modes that
    matter here) and a larger stable time step in the rotation-dominated modes.
    """
    x = np.ascontiguousarray(nodes_m, dtype=np.float64)
    off = np.ascontiguousarray(node_offsets, dtype=np.int64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise FiberpipeError(f"nodes must be an (N, 3) array, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise FiberpipeError("nodes contain NaN or inf")
    if off.ndim != 1 or off.size < 2 or off[0] != 0 or off[-1] != x.shape[0] or np.any(np.diff(off) < 2):
        raise FiberpipeError("node_offsets must start at 0, end at N and give every fiber ≥ 2 nodes")
    F = off.size - 1
    r = np.broadcast_to(np.asarray(radius_m, dtype=np.float64), (F,)).copy()
    if np.any(~(r > 0)):
        raise FiberpipeError("fiber radius must be > 0")
    if not mass_scale > 0:
        raise FiberpipeError(f"mass_scale must be > 0, got {mass_scale}")
    if not rotary_inertia_scale > 0:
        raise FiberpipeError(f"rotary_inertia_scale must be > 0, got {rotary_inertia_scale}")
    counts = np.diff(off)
    node_fiber = np.repeat(np.arange(F, dtype=np.int64), counts)
    is_last = np.zeros(x.shape[0], bool)
    is_last[off[1:] - 1] = True
    el_n1 = np.nonzero(~is_last)[0].astype(np.int64)
    el_fiber = node_fiber[el_n1]
    L0 = np.linalg.norm(x[el_n1 + 1] - x[el_n1], axis=1)
    if np.any(L0 <= 1e-12):
        bad = int(np.argmin(L0))
        raise FiberpipeError(f"zero-length element {bad} in fiber {int(el_fiber[bad])}: remove duplicate points")
    q0 = np.empty((x.shape[0], 4))
    for i in range(F):
        q0[off[i]:off[i + 1]] = _frames_parallel_transport(x[off[i]:off[i + 1]])
    E, G, rho = material.youngs_modulus_pa, material.G, material.density_kg_m3
    re = r[el_fiber]
    A = math.pi * re ** 2
    I = math.pi * re ** 4 / 4.0
    Jp = 2.0 * I
    ks = material.shear_factor
    el_C = np.column_stack([ks * G * A, ks * G * A, E * A])
    el_D = np.column_stack([E * I, E * I, G * Jp])
    el_Dk = el_D / L0[:, None]
    gamma_rest = np.empty((el_n1.size, 3))
    theta_rest = np.empty((el_n1.size, 3))
    element_rest_strains(x, q0, el_n1, 1.0 / L0, gamma_rest, theta_rest)
    mass = np.zeros(x.shape[0])
    Jn = np.zeros((x.shape[0], 3))
    me = mass_scale * rho * A * L0 / 2.0
    for k in (0, 1):
        np.add.at(mass, el_n1 + k, me)
        np.add.at(Jn, el_n1 + k, mass_scale * rotary_inertia_scale * rho * L0[:, None] / 2.0 * np.column_stack([Jp, Jp, Jp]))
    rn = np.zeros(x.shape[0])
    cnt = np.zeros(x.shape[0])
    for k in (0, 1):
        np.add.at(rn, el_n1 + k, re)
        np.add.at(cnt, el_n1 + k, 1.0)
    return Model(
        nodes_m=x, quats0=q0, node_offsets=off, node_fiber=node_fiber, el_n1=el_n1, el_fiber=el_fiber,
        el_L0=L0, el_invL0=1.0 / L0, el_radius=re, el_C=np.ascontiguousarray(el_C),
        el_D=np.ascontiguousarray(el_D), el_Dk=np.ascontiguousarray(el_Dk),
        gamma_rest=gamma_rest, theta_rest=theta_rest, mass=mass, J=Jn, radius_node=rn / cnt,
        material=material, rotary_inertia_scale=float(rotary_inertia_scale), mass_scale=float(mass_scale),
    )


def model_from_mesh(mesh, material: Material, *, rotary_inertia_scale: float = 1.0, mass_scale: float = 1.0) -> Model:
    """Build a :class:`Model` from a ``fiberpipe.model.mesh.Mesh`` (fields ``nodes_m``,
    ``node_offsets``, ``radius_m``)."""
    return build_model(mesh.nodes_m, mesh.node_offsets, mesh.radius_m, material,
                       rotary_inertia_scale=rotary_inertia_scale, mass_scale=mass_scale)
