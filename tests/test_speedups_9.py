"""Issue 13, the per-frame EKF stage faster (ninth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios — the same associations and
selected landmarks, the same decisions, and the state and covariance after the update equal to 1e-9 (bit for bit
where the arithmetic is unchanged)."""

from __future__ import annotations

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.estimation import JointEKF, NewLandmark
from stablemarks.estimation import ekf as E

from .conftest import COV_PRIOR


# ------------------------------------------------------------------ the joint-compatibility trials
def associate_joint_reference(ekf, measured, pan=0.0, candidates=None, extra_cost=None, *, costs=None):
    """The former :meth:`~stablemarks.estimation.ekf.JointEKF.associate_joint`: every trial's joint NIS by a fresh
    stacked solve (:meth:`~JointEKF._joint_nis`)."""
    ids, z, d2, cost = ekf.association_costs(measured, pan, candidates, extra_cost) if costs is None else costs
    order = [(r, c) for r, c in zip(*np.nonzero((d2 <= ekf.config.gate) & np.isfinite(cost)), strict=True)]
    order.sort(key=lambda rc: cost[rc])
    chosen, used_r, used_c = [], set(), set()
    p = ekf.config.gate_probability
    if order:
        rows = ekf._rows(ids, "associate_joint")
        uv, J_I_X, J_I_l = ekf._project(rows, ekf._x, ekf._camera(pan))
    taken_r: list[int] = []
    for r, c in order:
        if r in used_r or c in used_c:
            continue
        trial = chosen + [(int(ids[r]), int(c))]
        tr = taken_r + [int(r)]
        nis = ekf._joint_nis(rows[tr], z[[j for _, j in trial]], uv[tr], J_I_X[tr], J_I_l[tr])
        if nis <= E._chi2_gate(2 * len(trial), 1.0 - p):
            chosen, taken_r = trial, tr
            used_r.add(r)
            used_c.add(c)
    return sorted(chosen, key=lambda q: q[1])


def _filters(scenario_frames, scenario_models, rng):
    """Per scenario frame: filters with a wall landmark for every selected candidate (as ``stablemarks bench``
    makes them), at the true pose and at perturbed ones with wider, correlated pose covariances (after an odometry
    prediction and an update: the landmarks correlated with the pose and each other), and the frame's measured
    columns ``(u_l, u_r)`` of its kept pairs."""
    config = Config()
    out = []
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        _, _, _, _, camera, world_map, X = frame
        if not model.selected:
            continue
        pairs = front.kept_pairs
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        for trial in range(6):
            scale = (1.0, 2.0, 4.0, 8.0, 3.0, 6.0)[trial]
            X0 = X if trial == 0 else X + rng.normal(0, [0.03, 0.03, 0.01]) * scale
            ekf = JointEKF(config.camera(camera), X0, COV_PRIOR * scale**2, config.ekf)
            ekf.add_landmarks([NewLandmark.wall(world_map[c.plane_id], c.s, c.edge) for c in model.selected],
                              np.diag([c.sigma_s**2 for c in model.selected]))
            if trial >= 4:
                ekf.predict([0.0, 0.0, 0.0], np.diag([0.02, 0.02, 0.01]) ** 2 * scale)
                chosen = associate_joint_reference(ekf, measured)[:2]
                if chosen:
                    ekf.update([(i, measured[j]) for i, j in chosen])
            out.append((ekf, measured))
    return out


def test_associate_joint_equals_the_reference(scenario_frames, scenario_models, monkeypatch):
    """Every scenario frame's filters (:func:`_filters`) and measured columns, also with random extra costs (some
    forbidding pairs) over random candidate subsets, and with the running factor made to hand every trial to the
    stacked solve (a tolerance of 1e300) or none (0): the same associations, in the same order."""
    rng = np.random.default_rng(61)
    cases = _filters(scenario_frames, scenario_models, rng)
    n = n_pairs = n_multi = 0
    for ekf, measured in cases:
        ids = ekf.landmark_ids
        calls = [dict(), dict(pan=0.0)]
        for _ in range(3):
            cand = [i for i in ids if rng.random() < 0.8] or ids
            extra = rng.uniform(0, 6, (len(cand), len(measured)))
            extra[rng.random(extra.shape) < 0.1] = np.inf
            calls.append(dict(candidates=cand, extra_cost=extra))
        for kw in calls:
            want = associate_joint_reference(ekf, measured, **kw)
            for tol in (E.NIS_DECISION_TOL, 0.0, 1e300):
                monkeypatch.setattr(E, "NIS_DECISION_TOL", tol)
                got = ekf.associate_joint(measured, **kw)
                monkeypatch.undo()
                assert got == want
            if kw.get("candidates") is not None:
                costs = ekf.association_costs(measured, 0.0, kw["candidates"], kw["extra_cost"])
                assert ekf.associate_joint(measured, costs=costs) == want
            n += 1
            n_pairs += len(want)
            n_multi += len(want) >= 3
    assert n > 100 and n_pairs > 300 and n_multi > 30


def test_sequential_trials_nis_equals_the_stacked_solve(scenario_frames, scenario_models):
    """The running factor's NIS of each trial (read back by making every trial stop at its gate, ``tol`` = 1e300,
    and computing it with the gates set to the trial's own NIS) against the stacked solve: equal to 1e-9 relative.
    Taken directly: the NIS of the chosen pairs, grown one pair at a time in the reference's order."""
    rng = np.random.default_rng(67)
    n = 0
    for ekf, measured in _filters(scenario_frames, scenario_models, rng):
        chosen = associate_joint_reference(ekf, measured)
        if not chosen:
            continue
        ids, z, _, _ = ekf.association_costs(measured, 0.0, None, None)
        rows = ekf._rows(ids, "test")
        uv, J_I_X, J_I_l = ekf._project(rows, ekf._x, ekf._camera(0.0))
        H5 = np.ascontiguousarray(np.concatenate([J_I_X, J_I_l], axis=2))
        idx5 = np.ascontiguousarray(ekf._idx5(rows))
        nu = z[None, :, :] - uv[:, None, :]
        row_of = {int(i): r for r, i in enumerate(ids)}
        tr = np.array([row_of[i] for i, _ in chosen], dtype=np.int64)
        tc = np.array([j for _, j in chosen], dtype=np.int64)
        for m in range(1, len(tr) + 1):
            want = ekf._joint_nis(rows[tr[:m]], z[tc[:m]], uv[tr[:m]], J_I_X[tr[:m]], J_I_l[tr[:m]])
            # gates bracketing ``want`` by 1e-9: the kernel must accept below and reject above
            for factor, accepted in ((1.0 + 1e-9, True), (1.0 - 1e-9, False)):
                gates = np.full(len(ids) + 1, want * factor)
                stop, got_r, _ = E._sequential_trials(ekf._P, H5, idx5, ekf._var_img, nu, tr[m - 1 : m],
                                                      tc[m - 1 : m], gates, 0, tr[: m - 1], tc[: m - 1], 0.0)
                assert stop == -1 and (len(got_r) == m) == accepted
            n += 1
    assert n > 100


def test_association_projection_equals_a_fresh_one(scenario_frames, scenario_models):
    """The projection :meth:`~JointEKF.associate_joint` now takes from :meth:`~JointEKF.association_costs` (the
    landmarks in view out of the projection of every candidate) against the one it made itself before
    (:meth:`~JointEKF._project` of the landmarks in view): the same numbers, bit for bit; and the same costs as the
    public method's."""
    rng = np.random.default_rng(71)
    n = 0
    for ekf, measured in _filters(scenario_frames, scenario_models, rng):
        for cand in (None, [i for i in ekf.landmark_ids if rng.random() < 0.6] or ekf.landmark_ids):
            costs, got = ekf._association_costs(measured, 0.0, cand, None)
            want = ekf._project(ekf._rows(costs[0], "test"), ekf._x, ekf._camera(0.0))
            for a, b in zip(got, want, strict=True):
                assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
            for a, b in zip(costs, ekf.association_costs(measured, 0.0, cand, None), strict=True):
                assert np.array_equal(a, b, equal_nan=True)
            n += 1
    assert n > 50


def test_idx5_equals_the_reference(scenario_frames, scenario_models):
    """:meth:`~JointEKF._idx5` filled in place against the former concatenation, for every subset size."""
    for ekf, _ in _filters(scenario_frames, scenario_models, np.random.default_rng(73))[:10]:
        for m in range(ekf.n_landmarks + 1):
            rows = np.arange(m)
            want = np.concatenate([np.broadcast_to(np.arange(3), (m, 3)), ekf._idx2[rows]], axis=1)
            got = ekf._idx5(rows)
            assert got.dtype == want.dtype and np.array_equal(got, want)


# ------------------------------------------------------------------ the Joseph update's mirror
def mirror_upper_reference(diag):
    """The former mirroring step of :func:`~stablemarks.estimation.ekf._add_sym_rank` (``E._mirror_upper``)."""
    diag[...] = np.triu(diag) + np.triu(diag, 1).T


def add_sym_rank_reference(P, A, K, block=256):
    """The former :func:`~stablemarks.estimation.ekf._add_sym_rank`: the production function with its mirroring
    step swapped back (:func:`mirror_upper_reference`)."""
    fast = E._mirror_upper
    E._mirror_upper = mirror_upper_reference
    try:
        E._add_sym_rank(P, A, K, block)
    finally:
        E._mirror_upper = fast


def test_add_sym_rank_equals_the_reference():
    """Random symmetric matrices of 3 to 700 dimensions (one to three strips, blocks of 256 and of 7), with exact
    zeros and negative zeros in them, and rank-2r updates: the same bits (``-0.0`` and ``+0.0`` told apart)."""
    rng = np.random.default_rng(79)
    for n, r, block in [(3, 1, 256), (14, 3, 256), (40, 6, 7), (300, 6, 256), (700, 2, 256), (9, 4, 4)]:
        M = rng.normal(size=(n, n))
        P = M @ M.T
        P[rng.random((n, n)) < 0.05] = 0.0
        P = np.triu(P) + np.triu(P, 1).T
        P[0, 1] = P[1, 0] = -0.0
        A, K = rng.normal(size=(n, r)), rng.normal(size=(n, r))
        A[0], K[0] = 0.0, -0.0  # a row whose update is an exact (signed) zero
        got, want = P.copy(), P.copy()
        E._add_sym_rank(got, A, K, block)
        add_sym_rank_reference(want, A, K, block)
        assert got.tobytes() == want.tobytes()


def test_update_equals_the_reference(scenario_frames, scenario_models, monkeypatch):
    """Every scenario frame's filters, associated and updated (:meth:`~JointEKF.select_for_update`,
    :meth:`~JointEKF.update`, also iterated) with this pass's code and with the former association, ranking and
    mirror swapped back: the same pairs chosen, the same state and covariance bit for bit, the covariance exactly
    symmetric and positive semi-definite."""
    n = 0
    for ekf, measured in _filters(scenario_frames, scenario_models, np.random.default_rng(83)):
        for iterations in (1, 3):
            got, want = ekf.copy(), ekf.copy()
            chosen = got.select_for_update(got.associate_joint(measured, 0.0))
            res = got.update([(i, measured[j]) for i, j in chosen], iterations=iterations)
            with monkeypatch.context() as mp:
                mp.setattr(E, "_mirror_upper", mirror_upper_reference)
                ref_chosen = select_for_update_reference(want, associate_joint_reference(want, measured))
                ref = want.update([(i, measured[j]) for i, j in ref_chosen], iterations=iterations)
            assert chosen == ref_chosen
            assert got.state.tobytes() == want.state.tobytes() and got.cov.tobytes() == want.cov.tobytes()
            assert np.array_equal(res.nis, ref.nis) and res.nis_total == ref.nis_total
            P = got.cov
            assert np.array_equal(P, P.T) and np.linalg.eigvalsh(P).min() > -1e-12
            n += bool(chosen)
    assert n > 50


# ------------------------------------------------------------------ the whole on-line loop
@pytest.mark.slow
@pytest.mark.parametrize("name", ["lab", "office", "hall"])
def test_run_online_equals_the_former_ekf(name, monkeypatch):
    """The on-line loop (:func:`~stablemarks.online.run_online`: the association of every frame by
    :func:`~stablemarks.estimation.association.associate_frame`, its updates, landmarks entered and dropped) over
    the first 16 frames of three scenarios, with this pass's EKF and with the former association, ranking and
    mirror swapped back: every frame's pose and pose covariance, landmark count and associations, and the final state
    and covariance, bit for bit."""
    from stablemarks.online import run_online
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.scenario import load_scenario
    from stablemarks.sim.source import SimulatedSource

    run = simulate_run(load_scenario(name))
    got = run_online(SimulatedSource(run, frames=16))
    monkeypatch.setattr(E.JointEKF, "associate_joint", associate_joint_reference)
    monkeypatch.setattr(E.JointEKF, "select_for_update", select_for_update_reference)
    monkeypatch.setattr(E, "_mirror_upper", mirror_upper_reference)
    want = run_online(SimulatedSource(run, frames=16))
    assert len(got.records) == len(want.records) == 16
    n_assoc = 0
    for a, b in zip(got.records, want.records, strict=True):
        assert a.pose.tobytes() == b.pose.tobytes() and a.cov_pose.tobytes() == b.cov_pose.tobytes()
        assert (a.n_landmarks, a.observed, a.associated, a.new, a.dropped) == (
            b.n_landmarks, b.observed, b.associated, b.new, b.dropped)
        assert np.array_equal(a.nis, b.nis)
        n_assoc += len(a.associated)
    assert got.ekf.state.tobytes() == want.ekf.state.tobytes() and got.ekf.cov.tobytes() == want.ekf.cov.tobytes()
    assert got.ekf.landmark_ids == want.ekf.landmark_ids and n_assoc > 20


# ------------------------------------------------------------------ the ranking by information gain
def select_for_update_reference(ekf, pairs, pan=0.0, k=None):
    """The former :meth:`~JointEKF.select_for_update`: ranked by :meth:`~JointEKF.information_gain`."""
    pairs = list(pairs)
    k = ekf.config.max_updates_per_frame if k is None else int(k)
    if not pairs:
        return []
    gain = ekf.information_gain([p[0] for p in pairs], pan)
    return [pairs[i] for i in np.argsort(-gain, kind="stable")[:k]]


def information_gain_reference(ekf, ids, pan=0.0):
    """The former :meth:`~JointEKF.information_gain`, in one piece."""
    rows = ekf._rows(ids, "information_gain")
    pred = ekf.predict_observation(ids, pan)
    P_XX = ekf._P[:3, :3]
    P_lX = ekf._P[ekf._idx2[rows][:, :, None], np.arange(3)[None, None, :]]
    C = pred.J_I_X @ P_XX + pred.J_I_l @ P_lX
    S_given_X = pred.S - C @ np.linalg.pinv(P_XX, hermitian=True) @ np.swapaxes(C, 1, 2)
    return 0.5 * (np.linalg.slogdet(pred.S)[1] - np.linalg.slogdet(S_given_X)[1])


def test_select_for_update_equals_the_reference(scenario_frames, scenario_models, monkeypatch):
    """Every scenario filter's landmarks in view (and random subsets, for k of 1 to 8; also from a pose whose
    heading variance is zero or tiny, where the pose covariance is singular or nearly): the closed-form gains
    within 1e-9 nat of :meth:`~JointEKF.information_gain` (bit for bit the former one) wherever they are finite,
    and the same pairs in the same order, with the fallback forced on (a gap of 1e300) and off."""
    rng = np.random.default_rng(89)
    n = n_nan = 0
    for ekf, _ in _filters(scenario_frames, scenario_models, rng):
        variants = [ekf]
        if rng.random() < 0.3:
            for var_th in (0.0, 1e-30):
                e = ekf.copy()
                e.reset_pose(e.pose, np.diag([0.05**2, 0.05**2, var_th]))
                variants.append(e)
        for e in variants:
            seen = e.visible(0.0)
            if not seen:
                continue
            want_gain = information_gain_reference(e, seen)
            assert e.information_gain(seen).tobytes() == want_gain.tobytes()
            fast = E._closed_form_gains(*e._information_terms(seen, 0.0))
            ok = np.isfinite(fast)
            n_nan += not ok.all()
            assert np.allclose(fast[ok], want_gain[ok], rtol=0, atol=1e-9)
            for _ in range(4):
                pairs = [(i, int(rng.integers(0, 50))) for i in seen if rng.random() < 0.7] or [(seen[0], 0)]
                k = int(rng.integers(1, 9))
                want = select_for_update_reference(e, pairs, k=k)
                for tol in (E.GAIN_RANK_TOL, 1e300, 0.0):
                    monkeypatch.setattr(E, "GAIN_RANK_TOL", tol)
                    assert e.select_for_update(pairs, k=k) == want
                    monkeypatch.undo()
                n += 1
    assert n > 200 and n_nan > 0
