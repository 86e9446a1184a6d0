"""The editors solve under one BLAS thread and give the caller's thread setting back."""

from __future__ import annotations

import numpy as np
import pytest
import threadpoolctl

from mocaplab.editing import PinPosition, SceneEditor, spatial


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture
def walk(cmu):
    return cmu("16_15").resample(30)[:60]


def test_solves_run_on_one_blas_thread_and_the_setting_is_restored(walk, monkeypatch):
    if not _blas_threads():
        pytest.skip("no BLAS library reported by threadpoolctl")
    seen: list[list[int]] = []
    solve = spatial.SpatialSolver.solve

    def spy(self, *args, **kwargs):
        seen.append(_blas_threads())
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(spatial.SpatialSolver, "solve", spy)
    p = walk.root_positions[:, [0, 2]]
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        outside = _blas_threads()
        ed = SceneEditor([walk], [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 50, p[50])])
        ed.drag(1, p[50] + [0.3, 0.1])
        assert _blas_threads() == outside, "the caller's BLAS threads are restored after each solve"
    assert len(seen) >= 2 and all(n == [1] * len(n) for n in seen), seen
    # an error inside the solve restores the setting too
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        outside = _blas_threads()
        with pytest.raises(IndexError):
            ed.drag(7, np.zeros(2))
        monkeypatch.setattr(spatial.SpatialSolver, "solve", lambda *a, **k: 1 / 0)
        with pytest.raises(ZeroDivisionError):
            ed.drag(1, p[50])
        assert _blas_threads() == outside
