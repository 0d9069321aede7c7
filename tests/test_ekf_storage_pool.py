"""The reuse of the filter's stored arrays (shipid.identify.ekf._stored_empty): a buffer is handed out
again only when no array or view of it is alive, and a run into reused buffers gives the same output as
one into fresh memory."""
from __future__ import annotations

import gc

import numpy as np

from shipid.identify import ekf as E
from shipid.identify import EKFIdentifier, run_ekf


def test_a_buffer_is_reused_only_when_nothing_holds_it():
    a = E._stored_empty((3, 50, 7, 11))
    b = E._stored_empty((3, 50, 7, 11))
    assert not np.shares_memory(a, b)  # both alive: two buffers
    a[...] = 1.0
    view = a[1]
    del a
    gc.collect()
    c = E._stored_empty((3, 50, 7, 11))
    assert not np.shares_memory(c, view) and not np.shares_memory(c, b)  # a view keeps its buffer taken
    del view, c
    gc.collect()
    d = E._stored_empty((3, 50, 7, 11))
    assert any(np.shares_memory(d, buf) for buf in E._pool)  # free again: reused, not a new allocation
    f32 = E._stored_empty((3, 50, 7, 11), np.float32)
    assert f32.dtype == np.float32 and f32.shape == (3, 50, 7, 11) and not np.shares_memory(f32, d)


def test_large_storage_is_not_pooled():
    n = E._POOL_ARRAY_BYTES // 8 + 1
    big = E._stored_empty((n,))
    assert not any(np.shares_memory(big, buf) for buf in E._pool)
    assert sum(buf.nbytes for buf in E._pool) <= E._POOL_BYTES + E._POOL_ARRAY_BYTES


def test_runs_into_reused_buffers_equal_fresh_ones(kcs_truth, kcs_logs):
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model").fit(kcs_logs["kcs_zz_p20_rpm"][0].iloc[:300])
    prob = ident.problem_
    first = run_ekf(prob, store=True, compact="ship")
    kept = {k: np.array(getattr(first, k)) for k in ("z_post", "P_post", "z_prior", "P_prior", "F")}
    del first
    gc.collect()
    other = run_ekf(prob, store=True, compact=True)  # another shape in between
    again = run_ekf(prob, store=True, compact="ship")
    for k, v in kept.items():
        assert np.array_equal(getattr(again, k), v, equal_nan=True), k
        assert not np.shares_memory(getattr(again, k), getattr(other, k))


def test_the_pool_stays_within_its_budget_and_keeps_buffers_in_use():
    n = E._POOL_ARRAY_BYTES // 8 // 2
    held = [E._stored_empty((n,)) for _ in range(2 * E._POOL_BYTES // E._POOL_ARRAY_BYTES + 2)]
    keep = held[0]
    del held
    gc.collect()
    E._stored_empty((n + 1,))  # a new size: beyond the budget the oldest free buffers are dropped
    assert sum(buf.nbytes for buf in E._pool) <= E._POOL_BYTES + E._POOL_ARRAY_BYTES
    assert any(np.shares_memory(keep, buf) for buf in E._pool)  # the one still in use stays
