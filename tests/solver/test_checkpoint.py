"""Checkpoint and resume of the solver: a run resumed from any checkpoint (after an HDF5 round trip)
equals the uninterrupted run bit for bit, including the contact hook's mutable data; a stop request
saves a checkpoint; a checkpoint of another config is refused."""

import signal

import numpy as np
import pytest
from numba import njit

from fiberpipe.errors import ArtifactError, FiberpipeError
from fiberpipe.solver import (ContactHook, Damping, Gravity, Material, Plates, SimulationSettings, Walls,
                              build_model, simulate)
from fiberpipe.solver.layout import ACC_PW
from fiberpipe.verification.case_config import contact_hook
from fiberpipe.solver.checkpoint import SimulationInterrupted, read_checkpoint, write_checkpoint

MAT = Material(15e9, 1380.0, 0.3)
R = 0.25e-3


def stack_model(n_fibers=3, n_el=10, L=3e-3):
    xs = []
    for k in range(n_fibers):
        x = np.zeros((n_el + 1, 3))
        x[:, 0] = np.linspace(0, L, n_el + 1)
        x[:, 1] = 0.05e-3 * np.sin(np.linspace(0, 3, n_el + 1) + k)  # slightly wavy: bending and twist
        x[:, 2] = k * 2 * R
        xs.append(x)
    return build_model(np.vstack(xs), np.arange(n_fibers + 1) * (n_el + 1), R, MAT)


@njit(cache=True)
def _counting_hook(x, q, v, w, f, mom, acc, t, dt, data):
    """A stand-in for fiber–fiber contact with mutable state: a step counter and a 'friction history'
    that feed back into the forces, so a resume that lost them would differ."""
    counter, hist = data
    counter[0] += 1
    hist[0] = 0.9 * hist[0] + 1e-6 * v[0, 2]
    f[0, 2] += 1e-3 * hist[0] + 1e-9 * np.sin(0.01 * counter[0])
    acc[ACC_PW] += 0.0
    return int(counter[0] % 3)


def scene():
    hook = ContactHook(_counting_hook, prepare=lambda model, sc: (np.zeros(1, np.int64), np.zeros(1)))
    return [Gravity([0, 0, -9.81e3]), Damping(2e3, 1e-9),
            Plates(axis="z", lower="moving", upper="fixed", displacement_m=0.02e-3, velocity_m_s=0.1),
            Walls({"y": (-0.6e-3, 0.6e-3)}), hook]


SETTINGS = dict(output_frames=6, history_every=7, chunk_steps=200, checkpoint_every=500)


def assert_same(a, b):
    assert a.steps == b.steps
    assert np.array_equal(a.frames_time, b.frames_time)
    assert np.array_equal(a.frames_positions, b.frames_positions)
    assert np.array_equal(a.frames_rotations, b.frames_rotations)
    assert a.history.keys() == b.history.keys()
    for k in a.history:
        assert np.array_equal(a.history[k], b.history[k], equal_nan=True), k
    for k in ("x", "q", "v", "w", "acc"):
        assert np.array_equal(getattr(a.final_state, k), getattr(b.final_state, k)), k


def test_resume_from_every_checkpoint_is_bit_for_bit(tmp_path):
    model = stack_model()
    saved = []
    ref = simulate(model, scene(), SimulationSettings(**SETTINGS), on_checkpoint=saved.append)
    assert ref.completed and len(saved) == ref.steps // 500  # 2700 steps -> 5 checkpoints
    assert [c.step for c in saved] == [500, 1000, 1500, 2000, 2500]
    for k, ck in enumerate(saved):
        path = write_checkpoint(tmp_path / f"ck{k}.h5", ck, config_sha256="abc")
        back = read_checkpoint(path, config_sha256="abc")
        assert back.term_data["contact"][0].dtype == np.int64 and back.term_data["contact"][0][0] == ck.step
        res = simulate(model, scene(), SimulationSettings(**SETTINGS), resume=back)
        assert_same(ref, res)
        assert any("resumed from a checkpoint" in n for n in res.notes)


def test_stop_request_saves_a_checkpoint_and_resumes(tmp_path):
    model = stack_model()
    ref = simulate(model, scene(), SimulationSettings(**SETTINGS))
    polls = {"n": 0}

    def should_stop():
        polls["n"] += 1
        return signal.SIGINT if polls["n"] == 4 else None

    saved = []
    with pytest.raises(SimulationInterrupted) as ei:
        simulate(model, scene(), SimulationSettings(**SETTINGS), on_checkpoint=saved.append, should_stop=should_stop)
    assert ei.value.exit_code == 130
    ck = ei.value.checkpoint
    # the 4th boundary of the grid (chunks of 200, checkpoints every 500, frames every ~549 steps)
    assert ck is saved[-1] and ck.step == 549 and ck.frames_time.size == 2
    path = write_checkpoint(tmp_path / "ck.h5", ck, config_sha256="k")
    assert_same(ref, simulate(model, scene(), SimulationSettings(**SETTINGS), resume=read_checkpoint(path)))


def test_checkpoint_of_another_config_is_refused(tmp_path):
    model = stack_model()
    saved = []
    simulate(model, scene(), SimulationSettings(**SETTINGS), on_checkpoint=saved.append)
    path = write_checkpoint(tmp_path / "ck.h5", saved[0], config_sha256="old-key")
    with pytest.raises(ArtifactError, match="different config"):
        read_checkpoint(path, config_sha256="new-key")
    ck = read_checkpoint(path)
    with pytest.raises(FiberpipeError, match="another config"):
        simulate(model, scene(), SimulationSettings(**dict(SETTINGS, history_every=5)), resume=ck)
    with pytest.raises(FiberpipeError, match="another config"):
        simulate(model, scene(), SimulationSettings(**dict(SETTINGS, dt_safety=0.5)), resume=ck)
    with pytest.raises(FiberpipeError, match="another mesh"):
        simulate(stack_model(n_fibers=2), scene(), SimulationSettings(**SETTINGS), resume=ck)
    with pytest.raises(ArtifactError, match="is a checkpoint artifact"):
        from fiberpipe.artifacts import read_mesh
        read_mesh(path)


def test_checkpoint_with_another_energy_layout_is_refused(tmp_path):
    """A checkpoint whose energy accumulators are not this version's layout is refused at read time
    (the step loop indexes them without bounds checks)."""
    import dataclasses

    model = stack_model()
    saved = []
    simulate(model, scene(), SimulationSettings(**SETTINGS), on_checkpoint=saved.append)
    old = dataclasses.replace(saved[0], acc=saved[0].acc[:-1])
    path = write_checkpoint(tmp_path / "ck.h5", old)
    with pytest.raises(ArtifactError, match="energy accumulators"):
        read_checkpoint(path)


def test_checkpoint_size_scales_with_the_model(tmp_path):
    model = stack_model()
    saved = []
    simulate(model, scene(), SimulationSettings(**SETTINGS), on_checkpoint=saved.append)
    path = write_checkpoint(tmp_path / "ck.h5", saved[-1])
    # state (14 floats/node) + frames so far + history rows: a few tens of kB for 33 nodes
    assert path.stat().st_size < 200_000


def test_resume_with_the_real_contact_hook_is_bit_for_bit(tmp_path):
    """Fiber–fiber contact + friction + plates: the hook's data (neighbour list, friction history,
    typed-list buffers grown in the kernel) round-trips through the checkpoint."""
    model = stack_model(n_fibers=3)

    def effects():
        return [Damping(1e4), Gravity([0, 0, -9.81]),
                Plates(axis="z", lower="moving", upper="fixed", displacement_m=0.02e-3, velocity_m_s=0.1, mu=0.3),
                contact_hook(model, friction=True, mu=0.3)]

    # default dt_safety (0.9): this scene once gained tens of m/s from the fiber–fiber friction (k_t per
    # segment pair, not per contact share: unstable tangential springs); see tests/solver/test_friction.py
    settings = dict(SETTINGS)
    saved = []
    ref = simulate(model, effects(), SimulationSettings(**settings), on_checkpoint=saved.append)
    assert np.max(ref.history["contacts"]) > 0
    for ck in (saved[0], saved[-1]):
        path = write_checkpoint(tmp_path / "ck.h5", ck)
        assert_same(ref, simulate(model, effects(), SimulationSettings(**settings), resume=read_checkpoint(path)))
