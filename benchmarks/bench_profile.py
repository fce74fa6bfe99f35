"""Where a paper-40 step spends its time: the step loop with its effects added one at a time, and
the kernels of one step timed alone, from saved states of the run (early phase and compacted phase).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_profile.py STATE.npz [STATE.npz ...]

States come from ``benchmarks/paper40_states.py`` (``make profile-paper40`` makes both and
runs this). Every variant restarts from a copy of the same state, runs ``--warmup`` steps (the
contact hook's first call and the neighbour list), then ``--steps`` timed steps, ``--repeats`` times
in rotation (variants alternate, so a load change on the machine hits them alike); best per variant.
Times are the process's CPU time (``time.process_time``): on a shared machine the wall time also
counts the time the process waits for a core.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from fiberpipe.benchmarks.scenes import load_state, scene

BASE = ["gravity", "damping", "constraints"]
VARIANTS = [
    ("beams + update (gravity, damping, axial lock)", BASE),
    ("+ plates, walls", BASE + ["plates", "walls"]),
    ("+ fiber–fiber contact", BASE + ["plates", "walls", "contact"]),
    ("+ friction (the paper-40 scene)", BASE + ["plates", "walls", "contact", "friction"]),
]


def _best(fn, n: int, repeats: int = 5) -> float:
    """Best wall time [s] of ``n`` calls of ``fn``, over ``repeats``."""
    best = np.inf
    for _ in range(repeats):
        t = time.process_time()
        for _ in range(n):
            fn()
        best = min(best, time.process_time() - t)
    return best / n


def step_variants(state_path, steps: int, warmup: int, repeats: int) -> list[dict]:
    """µs per step of the step loop for each effect set of ``VARIANTS``, from the same state."""
    from fiberpipe.solver.integrator import Integrator

    runs = []
    for name, eff in VARIANTS:
        model, effects, settings, dt = scene({"scene.effects": eff})
        runs.append((name, model, effects, dt))
    # the scene's own dt for every variant (the plates and the contact do not change it)
    dt = runs[-1][3]
    best = {name: np.inf for name, *_ in runs}
    info = {}
    for r in range(repeats):
        for name, model, effects, _ in runs:
            integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
            st = load_state(state_path)
            integ.advance(st, warmup)
            contact_on = any(term.name == "contact" for term, _, _ in integ.plan.terms)
            hook = integ.term_data("contact") if contact_on else None
            b0 = int(hook.stats.n_builds[0]) if contact_on else 0
            t = time.process_time()
            integ.advance(st, steps)
            best[name] = min(best[name], (time.process_time() - t) / steps)
            if contact_on:
                s = hook.stats
                info[name] = {"pairs": int(s.n_pairs[0]), "active": int(s.n_active[0]),
                              "builds_per_step": (int(s.n_builds[0]) - b0) / steps}
    return [{"variant": name, "us_per_step": 1e6 * best[name], **info.get(name, {})} for name, *_ in runs]


def kernel_times(state_path) -> dict:
    """µs per call of the kernels of one step, alone, on the state's positions."""
    from fiberpipe.solver._kernels_beam import EB_SIZE, beam_pass_all, beam_resultants
    from fiberpipe.solver._kernels_boundary import plane_contacts
    from fiberpipe.solver.contact_pairs import gauss_points
    from fiberpipe.solver.contact_potential import contact_forces_pot
    from fiberpipe.solver.contact_state import new_records
    from fiberpipe.solver.friction import friction_forces_ex, plane_friction
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.neighbours import build_pairs, max_displacement2_speed2

    model, effects, settings, dt = scene()
    integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
    st = load_state(state_path)
    integ.advance(st, 2)
    x, q, v = st.x, st.q, st.v
    m = integ.model_arrays
    eb = np.zeros((model.n_elements, EB_SIZE))
    sp = np.zeros((0, 6))
    out = {}
    work = integ._kernel_args()[1]
    out["beam pass, vectorised (beam_pass_all, the step loop's)"] = _best(lambda: beam_pass_all(x, q, m, work), 2000)
    out["beam pass, per element (beam_resultants, large rotations and β > 0)"] = _best(lambda: beam_resultants(
        x, q, m.el_n1, m.el_invL0, m.el_C, m.el_Dk, m.gamma_rest, m.theta_rest, eb, False, 0.0, sp, m.node_offsets), 2000)
    sc = integ.scene
    n, P = x.shape[0], sc.pl_axis.size
    f = np.zeros((n, 3))
    pf, pi, pv = np.zeros(P), np.zeros(n * P, np.int64), np.zeros(n * P)
    out["planes (plane_contacts, all nodes)"] = _best(lambda: plane_contacts(
        x, m.radius_node, integ.planes.k_pen, integ.planes.onset, sc.pl_axis, sc.pl_sign, integ.planes.pos, f, pf, pi, pv,
        (sc.pl_rect_half, sc.pl_rect_centre)), 2000)
    data = integ.term_data("contact")
    segs, prm = data.segs, data.params
    pl = data.lists[1]
    out["neighbour list build (build_pairs)"] = _best(lambda: build_pairs(
        x, segs.nodes, segs.radius, segs.fiber, segs.arc, prm.skin_m, prm.exclusion_m, pl.pairs, pl.keys), 20)
    out["displacement test (max_displacement2_speed2)"] = _best(lambda: max_displacement2_speed2(x, data.x_ref, v), 2000)
    npairs = int(data.stats.n_pairs[0])
    pairs = data.lists[0].pairs
    gxi, gw = gauss_points(len(prm.gauss_xi))
    # the default normal kernel (potential formulation) on every candidate: records without the gap
    # array, so no pair is skipped (the step loop skips those whose gap exceeds their path bound)
    recs = new_records(max(npairs, 1))._replace(gap=np.zeros(0))
    none = np.zeros(0)
    res = contact_forces_pot(x, segs.nodes, segs.radius, segs.arc, pairs, npairs, prm.law_id, prm.law_params, gxi,
                             gw, prm.onset_m, f, recs, none, 0.0)
    out["contact, every candidate evaluated (contact_forces_pot)"] = _best(lambda: contact_forces_pot(
        x, segs.nodes, segs.radius, segs.arc, pairs, npairs, prm.law_id, prm.law_params, gxi, gw, prm.onset_m, f,
        recs, none, 0.0), 500)
    # the friction kernels of the step on its pairs in contact and plane candidates (the records and
    # histories of the state's last step; each call restarts the histories it visits, as a contact
    # that opened would: the same work per call)
    rec, n_act, calls = data.records[0], int(data.stats.n_active[0]), int(data.stats.calls[0])
    out["friction, fiber–fiber (friction_forces_ex, pairs in contact)"] = _best(lambda: friction_forces_ex(
        v, segs.nodes, pairs, npairs, rec, prm.mu, prm.kt_n_per_m, dt, data.lists[0].friction, f, n_act, calls), 2000)
    planes_friction = integ.term_data("plane_friction")
    out["friction, plates and walls (plane_friction, candidate nodes)"] = _best(lambda: plane_friction(
        v, planes_friction, dt, int(planes_friction.calls[0])), 2000)
    out["_candidates"] = npairs
    out["_in_contact"] = int(res[1])
    out["_elements"] = model.n_elements
    out["_nodes"] = n
    return out


def _builds(r: dict) -> str:
    return "" if "builds_per_step" not in r else f"{1000 * r['builds_per_step']:.2f}"


def table(state_path, variants: list[dict], kernels: dict) -> list[str]:
    lines = [f"State `{os.path.basename(str(state_path))}` (t = {float(np.load(state_path)['t']) * 1e3:.2f} ms): "
             f"{kernels['_candidates']} candidate pairs, {kernels['_in_contact']} in contact.", "",
             "| step loop with | µs/step | added by this line (µs/step) | candidates | in contact | list builds per 1000 steps |",
             "|---|---|---|---|---|---|"]
    prev = 0.0
    for r in variants:
        lines.append(f"| {r['variant']} | {r['us_per_step']:.1f} | {r['us_per_step'] - prev:+.1f} | "
                     f"{r.get('pairs', '')} | {r.get('active', '')} | "
                     f"{_builds(r)} |")
        prev = r["us_per_step"]
    lines += ["", "| kernel alone | µs per call |", "|---|---|"]
    for k, v in kernels.items():
        if not k.startswith("_"):
            lines.append(f"| {k} | {1e6 * v:.1f} |")
    return lines


def main(argv=None) -> list[str]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("states", nargs="+")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--warmup", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    lines = [f"load average {os.getloadavg()[0]:.2f} (1 min) at the start", ""]
    for s in a.states:
        v = step_variants(s, a.steps, a.warmup, a.repeats)
        k = kernel_times(s)
        lines += table(s, v, k) + [""]
        print("\n".join(table(s, v, k)), flush=True)
    lines.append(f"load average {os.getloadavg()[0]:.2f} (1 min) at the end")
    print(lines[-1])
    return lines


if __name__ == "__main__":
    main()
