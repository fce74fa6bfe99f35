"""The step loop's arguments as named structures (NamedTuples of arrays, which numba compiles).

Static model data, the scene's effect arrays, the per-step state and the work buffers stay apart,
in the manner of warp.sim's Model / State / Integrator: the step loop
:func:`fiberpipe.solver._kernels_integrate.advance_plain` reads ``ModelArrays`` and ``SceneKernel``
(never written), advances ``StepState`` in place and uses ``WorkArrays`` as scratch and output.
Fibers are flat arrays with CSR offsets (fiber k owns nodes ``node_offsets[k] … node_offsets[k+1]−1``
and elements ``node − k``). SI units throughout.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ElementForces(NamedTuple):
    """The beam pass's resultants per element at index first node + 1, (N + 1,) each: ``n`` the spatial
    force (N), ``m`` the moment (N·m), ``h = ½ (x_2 − x_1) × n`` (N·m). Node ``i`` gets ``(+n, m + h)``
    from entry ``i + 1`` and ``(−n, h − m)`` from entry ``i``; entries without an element stay 0. Nine
    separate arrays: the vectorised loops need their writes and strided reads in distinct arrays
    (``fiberpipe._vectorise``)."""

    n0: np.ndarray
    n1: np.ndarray
    n2: np.ndarray
    m0: np.ndarray
    m1: np.ndarray
    m2: np.ndarray
    h0: np.ndarray
    h1: np.ndarray
    h2: np.ndarray


class ModelArrays(NamedTuple):
    """Static arrays of a :class:`fiberpipe.solver.model.Model` (per element E, per node N)."""

    el_n1: np.ndarray         # (E,) int64, first node of each element
    el_invL0: np.ndarray      # (E,) 1/m, inverse rest length
    el_C: np.ndarray          # (E, 3) N, axial and shear stiffness EA, GA_s, GA_s
    el_Dk: np.ndarray         # (E, 3) N·m², torsion and bending stiffness GJ, EI, EI
    gamma_rest: np.ndarray    # (E, 3) rest translational strain
    theta_rest: np.ndarray    # (E, 3) rest curvature × length
    mass: np.ndarray          # (N,) kg, lumped (scaled) mass
    inv_mass: np.ndarray      # (N,) 1/kg
    J: np.ndarray             # (N, 3) kg·m², body-frame rotary inertia
    inv_J: np.ndarray         # (N, 3) 1/(kg·m²)
    radius_node: np.ndarray   # (N,) m, fiber radius at each node
    x0: np.ndarray            # (N, 3) m, rest positions (the constant loads' work reference)
    node_offsets: np.ndarray  # (F+1,) int64, CSR offsets of the fibers' nodes
    beams: np.ndarray         # (14, N) the element parameters by first node (_kernels_beam.node_beams)


class PlaneArrays(NamedTuple):
    """Rigid planes (plates and walls), one entry per plane P; the last four are per-step outputs."""

    axis: np.ndarray       # (P,) int64, axis normal to the plane
    sign: np.ndarray       # (P,) +1 pushes towards +axis (lower plate, low wall), −1 otherwise
    pos0: np.ndarray       # (P,) m, initial position
    # the prescribed travel, a table of S entries per plane (_kernels_boundary.path_travel): the
    # one-segment loading is S = 1; a loading path is its moves with a hold after each but the last
    move: np.ndarray       # (P, S) m, travel towards the bundle at the end of each entry (0: fixed)
    T: np.ndarray          # (P, S) s, duration of each entry
    ta: np.ndarray         # (P, S) s, acceleration time of each entry's ramp
    mode: np.ndarray       # (P,) int64, ramp code (_kernels_boundary.RAMP_*)
    hist_col: np.ndarray   # (P,) int64, history column of the reaction (-1: none)
    k_pen: np.ndarray      # (N,) N/m, penalty stiffness per node (size 0 without planes)
    onset: np.ndarray      # (N,) m, penalty onset length per node (_kernels_boundary.plane_onset)
    pos: np.ndarray        # (P,) m, out: position at t_n
    force: np.ndarray      # (P,) N, out: reaction, positive when pressed
    pen_idx: np.ndarray    # (N·P,) int64, out: node·3 + axis of each touching node
    pen_f: np.ndarray      # (N·P,) N, out: the penalty force component along the axis
    # the nodes near each plane (_kernels_boundary.plane_candidates), which the penalty visits while
    # no node and no plane can have moved by the list's margin since it was taken
    cand_idx: np.ndarray   # (N·P,) int64, the listed nodes, plane after plane
    cand_off: np.ndarray   # (P + 1,) int64, CSR offsets into cand_idx
    cand_fn: np.ndarray    # (N·P,) N, out: each listed node's normal force (−1: not touching), for the friction
    cand_pos: np.ndarray   # (P,) m, plane positions when listed
    cand_slack: np.ndarray  # (2,) m: the margin left (Σ Δt max|v| subtracted each step), the list's margin
    # a finite plate's rectangle along the plane's two axes in x, y, z order (_kernels_boundary.in_plane_axes)
    rect_half: np.ndarray  # (P, 2) m, its half extents (0: the plane is infinite)
    rect_centre: np.ndarray  # (P, 2) m, its centre


class DriveArrays(NamedTuple):
    """Prescribed rigid motions of whole fibers, one entry per drive D."""

    vec: np.ndarray    # (D, 3) m, total displacement
    T: np.ndarray      # (D,) s, duration of the ramp
    ta: np.ndarray     # (D,) s, acceleration time
    mode: np.ndarray   # (D,) int64, ramp code
    v: np.ndarray      # (D, 3) m/s, out: this step's prescribed velocity


class Fixity(NamedTuple):
    """Fixed and driven degrees of freedom as factors of the node update (1 free, 0 prescribed)."""

    free_x: np.ndarray      # (N,) 0 where x is fixed or driven
    free_y: np.ndarray      # (N,)
    free_z: np.ndarray      # (N,)
    free_rot: np.ndarray    # (N,) 0 where the rotation is fixed (FIX_ROT or driven)
    v_pres: np.ndarray      # (N, 3) m/s, the prescribed velocity of the driven nodes this step (else 0)
    driven: np.ndarray      # (D_n,) int64, the driven nodes


class SceneKernel(NamedTuple):
    """The effects' arrays the step loop reads (size 0 where an effect is absent)."""

    alpha_per_s: float        # mass-proportional damping α
    beta_s: float             # stiffness-proportional damping β
    f_ext: np.ndarray         # (N, 3) N, constant loads (gravity, point and line loads) or (0, 3)
    fix_mask: np.ndarray      # (N,) uint8, layout.FIX_* and DRIVEN bits, or (0,)
    node_drive: np.ndarray    # (N,) int64, drive of each driven node (-1: none)
    drives: DriveArrays
    planes: PlaneArrays
    fixity: Fixity
    friction_f: np.ndarray    # (N, 3) N, the friction forces the terms leave for the update, or (0, 3)


class StepState(NamedTuple):
    """The state the step loop advances in place (views of :class:`fiberpipe.solver.state.State`)."""

    x: np.ndarray    # (N, 3) m, positions at t_n
    q: np.ndarray    # (N, 4) unit quaternions (w, x, y, z), node frames
    v: np.ndarray    # (N, 3) m/s, velocities at t_{n−½}
    w: np.ndarray    # (N, 3) rad/s, body angular velocities at t_{n−½}
    acc: np.ndarray  # (layout.ACC_SIZE,) J, energy accumulators


class WorkArrays(NamedTuple):
    """Scratch and output buffers of the step loop."""

    f: np.ndarray            # (N, 3) N, forces of everything but the beams at t_n
    mom: np.ndarray          # (N, 3) N·m, spatial moments of everything but the beams
    ef: ElementForces        # the beams' element resultants, gathered per node by the update
    eb: np.ndarray           # (E, EB_SIZE) scratch of the exact element pass (large rotations, β > 0)
    strain_prev: np.ndarray  # (E, 6) last step's strains (stiffness-proportional damping) or (0, 6)
    hist: np.ndarray         # (rows, layout.H_WALL + walls) history rows
    task_sums: np.ndarray    # (tasks, 9) the parallel node passes' sums per task (solver.threads > 1)
    acc_before: np.ndarray   # (layout.ACC_SIZE,) the accumulators at a history row's step's start
    zeros: np.ndarray        # (N, 3) zeros: the force array the update reads where a scene has none


class StepControl(NamedTuple):
    """Scalars of one call of the step loop."""

    dt_s: float
    n_steps: int
    t_start_s: float
    step_start: int
    h_row: int            # next history row to write
    history_every: int    # steps between history rows
    v_limit_m_s: float    # a node faster than this is a blow-up
    x_limit_m: float      # a node farther than this from its rest position is a run-away
    e_ref_J: float        # floor of the energy scale of the blow-up check
