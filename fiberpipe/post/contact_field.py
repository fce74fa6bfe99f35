"""Fiber–fiber contact forces of an output frame, as a field for ParaView and per-frame statistics.

The normal contact force is a function of the positions alone (a penalty law), so it is evaluated
again on each stored frame with the scene's own law, formulation, Gauss points and onset and the
solver's own kernels (neighbour list, contact pass); the friction part, which depends on the slip
history, and the release of initial overlaps, which a frame does not keep, are not included.
"""

from __future__ import annotations

import numpy as np


def frame_contact_forces(mesh, frames_positions: np.ndarray, scene_cfg, material_cfg) -> dict:
    """Normal contact force per node and contact statistics for every frame.

    Parameters
    ----------
    mesh : fiberpipe.model.mesh.Mesh
    frames_positions : (K, N, 3) float64, m
    scene_cfg, material_cfg : the config's ``scene`` and ``material`` sections

    Returns
    -------
    dict with ``contact_force`` (K, N, 3) N, ``contacts`` (K,) active segment pairs,
    ``contacts_per_fiber`` (K, F) active pairs each fiber takes part in, ``max_normal_force``
    (K,) N, ``max_penetration`` (K,) m.
    """
    from fiberpipe.solver.laws import law_from_config
    from fiberpipe.solver.neighbours import VerletList, segment_arclength

    law = law_from_config(scene_cfg.contact, material_cfg)
    seg = mesh.elements()
    seg_fiber = mesh.element_fiber()
    seg_radius = mesh.element_radius_m()
    arc = segment_arclength(seg, seg_fiber, mesh.nodes_m)
    verlet = VerletList(seg, seg_radius, seg_fiber, arc, skin_m=0.05 * float(seg_radius.max()))
    # the run's contact pass with the run's Gauss points and onset
    potential = _potential_pass(seg, seg_radius, arc, law, scene_cfg.contact)
    K, N = frames_positions.shape[:2]
    out = {
        "contact_force": np.zeros((K, N, 3)),
        "contacts": np.zeros(K, np.int64),
        "contacts_per_fiber": np.zeros((K, mesh.n_fibers), np.int64),
        "max_normal_force": np.zeros(K),
        "max_penetration": np.zeros(K),
    }
    for k in range(K):
        x = np.ascontiguousarray(frames_positions[k])
        verlet.build(x)
        n = verlet.n_pairs
        f = out["contact_force"][k]
        if n == 0:
            continue
        records = potential(x, verlet.pairs, n, f)
        fn = np.asarray(records.fn[:n])
        active = fn > 0
        pairs = verlet.pairs[:n][active]
        out["contacts"][k] = int(active.sum())
        np.add.at(out["contacts_per_fiber"][k], seg_fiber[pairs[:, 0]], 1)
        np.add.at(out["contacts_per_fiber"][k], seg_fiber[pairs[:, 1]], 1)
        if active.any():
            out["max_normal_force"][k] = float(fn[active].max())
            out["max_penetration"][k] = float(np.asarray(records.delta[:n])[active].max())
    return out


def _potential_pass(seg, seg_radius, arc, law, contact_cfg):
    """``(x, pairs, n, f) -> records``: the contact pass's normal forces on the candidate pairs, added
    into ``f`` (the kernel the run's hook binds for ``law``; no initial-overlap offsets, which a frame
    does not keep)."""
    from fiberpipe.solver.contact_pairs import gauss_points
    from fiberpipe.solver.contact_potential import potential_kernels_for
    from fiberpipe.solver.contact_state import new_records

    kernel = potential_kernels_for(law)
    gxi, gw = gauss_points(int(contact_cfg.gauss_points))
    seg = np.ascontiguousarray(seg, dtype=np.int64)
    radius = np.ascontiguousarray(seg_radius, dtype=np.float64)
    onset_m = float(contact_cfg.onset)

    def run(x, pairs, n, f):
        records = new_records(max(n, 1))
        kernel(x, seg, radius, arc, np.ascontiguousarray(pairs[:n], dtype=np.int64), n, law.law_id, law.params(),
               gxi, gw, onset_m, f, records, np.zeros(0), 0.0)
        return records

    return run
