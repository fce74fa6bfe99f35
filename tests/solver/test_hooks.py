"""Per-step terms given by a kernel (``ContactHook``) declare the force arrays they write; a scene runs
any number of them in turn, and at most one hands its forces to the node update."""

import numpy as np
import pytest
from numba import njit

from fiberpipe.errors import FiberpipeError
from fiberpipe.solver import ContactHook, Damping, Material, SimulationSettings, build_model, simulate

from _hooks import lift  # f[:, 2] += data[0][0], its work booked; data[0][1] contacts

MAT = Material(15e9, 1380.0, 0.3)


@njit(cache=True)
def _own_array_lift(x, q, v, w, f, mom, acc, t, dt, data):
    data[1][:, 2] += data[0][0]  # into the hook's own force array, which the step loop applies
    return 1


@njit(cache=True)
def _own_forces(data):
    return data[1]


def _model():
    s = np.linspace(0, 1, 6)[:, None]
    return build_model(s * np.array([1e-3, 0, 0]), np.array([0, 6]), 0.25e-3, MAT)


def test_a_hook_writing_its_own_array_moves_the_fiber_as_one_adding_into_f():
    m = _model()
    a = simulate(m, [ContactHook(lift, (np.array([1e-4, 1.0]),)), Damping(1e3)],
                 SimulationSettings(end_time_s=1e-4, output_frames=2))
    own = ContactHook(_own_array_lift, (np.array([1e-4]), np.zeros((m.n_nodes, 3))), forces_of=_own_forces)
    b = simulate(m, [own, Damping(1e3)], SimulationSettings(end_time_s=1e-4, output_frames=2))
    assert a.frames_positions[-1, 0, 2] > 0
    np.testing.assert_allclose(b.frames_positions[-1], a.frames_positions[-1], rtol=0, atol=1e-15)
    # the own array's work is booked by the step loop as contact work (ALLPW), as the first hook books it
    wa, wb = a.history["energy/contact"][-1], b.history["energy/contact"][-1]
    assert wb > 0 and wb == pytest.approx(wa, rel=0.01)


def test_two_hooks_run_in_turn_and_add_their_forces():
    """Two lifting terms of half the force each move the fiber as one term of the whole force."""
    m = _model()
    whole = simulate(m, [ContactHook(lift, (np.array([1e-4, 1.0]),)), Damping(1e3)],
                     SimulationSettings(end_time_s=1e-4, output_frames=2))
    one = ContactHook(lift, (np.array([0.5e-4, 1.0]),))
    two = ContactHook(lift, (np.array([0.5e-4, 1.0]),))
    two.name = "second"
    halves = simulate(m, [one, two, Damping(1e3)], SimulationSettings(end_time_s=1e-4, output_frames=2))
    np.testing.assert_allclose(halves.frames_positions[-1], whole.frames_positions[-1], rtol=0, atol=1e-15)
    # each counts one contact: the history's column is their sum
    assert halves.history["contacts"][-1] == 2 * whole.history["contacts"][-1] == 2


def test_a_second_term_handing_its_forces_to_the_update_is_refused():
    m = _model()
    one = ContactHook(_own_array_lift, (np.array([1e-4]), np.zeros((m.n_nodes, 3))), forces_of=_own_forces)
    two = ContactHook(_own_array_lift, (np.array([1e-4]), np.zeros((m.n_nodes, 3))), forces_of=_own_forces)
    two.name = "second"
    with pytest.raises(FiberpipeError, match="one may"):
        simulate(m, [one, two], SimulationSettings(end_time_s=1e-5, output_frames=2))


@pytest.mark.parametrize("threads", [1, 2])
def test_threads_pick_the_hooks_threaded_kernel(threads):
    """solver.threads > 1 runs the hook's ``kernel_threads`` (the built-in hook's: the potential pass
    with its pairs in tasks); one thread, or a hook without one, its ``kernel``."""
    from fiberpipe.solver._kernels_integrate import no_record, step_loop_for
    from fiberpipe.solver.terms.contact import (contact_forces_of, contact_step,
                                                contact_step_potential_threads)
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.verification.case_config import contact_hook

    m = _model()
    hook = contact_hook(m)
    assert hook.kernel is contact_step and hook.kernel_threads is contact_step_potential_threads
    integ = Integrator(m, [hook], 1e-8, threads=threads)
    expect = contact_step_potential_threads if threads > 1 else contact_step
    assert integ.plan.loop is step_loop_for([expect], [no_record], forces_of=contact_forces_of, threads=threads,
                                            cache_names=[hook.cache_name])
    plain = Integrator(m, [ContactHook(lift, (np.array([1e-4, 1.0]),))], 1e-8, threads=threads)
    assert plain.plan.loop is step_loop_for([lift], [no_record], threads=threads, cache_names=[None])


def test_a_run_warns_when_numba_allows_fewer_threads_than_asked(monkeypatch):
    """solver.threads above NUMBA_NUM_THREADS (read once, when numba starts) runs on fewer threads:
    the run says so instead of running slower in silence."""
    import numba

    from fiberpipe.solver.integrator import _usable_threads, threads_warning

    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 1)
    assert _usable_threads(2) == 1 and _usable_threads(1) == 1
    assert threads_warning(2).startswith("solver.threads is 2 but NUMBA_NUM_THREADS allows 1: the run uses 1")
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 4)
    assert _usable_threads(2) == 2 and threads_warning(2) is None
