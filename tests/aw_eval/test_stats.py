"""Statistics of Appendix B.1 against hand-computed and independently computed values."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from aw_eval.stats import (
    Design,
    TaskMeta,
    bootstrap_overall,
    draw_weights,
    holm,
    object_contributions,
    object_counts,
    paired_object_bootstrap,
    pairwise_tests,
    randomization_pvalues,
    reference_effects,
    weighted_median,
)
from tests.aw_eval.score_helpers import first_k, paper_design, sr_row

PN_NR, PN_IR = ("partnet", "none"), ("partnet", "image")
IK, AB, FB = ("ikea_manual", "manual"), ("assemblybench", "manual"), ("fantastic_breaks", "none")


# ---- eq. 3 ---------------------------------------------------------------------------------


def test_table1_overall_astra_and_qwen():
    """Per-source SR columns of the paper's Table 1 reproduce its Overall column."""
    d = paper_design()
    astra = first_k(d, {PN_NR: 3, PN_IR: 8, IK: 13, AB: 11, FB: 18})  # 15/40/65/55/90 %
    qwen = first_k(d, {PN_NR: 1, PN_IR: 0, IK: 0, AB: 2, FB: 7})  # 5/0/0/10/35 %
    opus = first_k(d, {PN_NR: 2, PN_IR: 5, IK: 10, AB: 8, FB: 14})  # 10/25/50/40/70 %
    overall = d.weights @ np.stack([astra, qwen, opus]).T * 100
    assert overall[0] == pytest.approx(59.375)
    assert overall[1] == pytest.approx(11.875)
    assert overall[2] == pytest.approx(44.375)
    # as printed (four significant digits in the paper's table)
    assert [f"{x:.1f}" for x in overall] == ["59.4", "11.9", "44.4"]
    # the cell means are the source columns
    cells = d.cell_weights() @ astra * 100
    assert cells.tolist() == pytest.approx([15, 40, 65, 55, 90])


def test_weights_generalize_to_custom_sources_and_task_weights():
    tasks = [
        TaskMeta("a1", "mine", "none", "x", 1.0),
        TaskMeta("a2", "mine", "none", "y", 3.0),
        TaskMeta("b1", "other", "image", "z"),
    ]
    d = Design.from_tasks(tasks)
    assert d.sources == ("mine", "other")
    assert d.weights.tolist() == pytest.approx([0.125, 0.375, 0.5])
    assert d.weights.sum() == pytest.approx(1.0)


def test_design_rejects_bad_input():
    with pytest.raises(ValueError, match="at least one task"):
        Design.from_tasks([])
    with pytest.raises(ValueError, match="duplicate"):
        Design.from_tasks([TaskMeta("a", "s", "none", "o"), TaskMeta("a", "s", "none", "p")])
    with pytest.raises(ValueError, match="weight"):
        Design.from_tasks([TaskMeta("a", "s", "none", "o", 0.0)])


# ---- bootstrap -----------------------------------------------------------------------------


def test_bootstrap_of_a_constant_is_the_constant():
    d = paper_design(5)
    values = np.full((3, d.n_tasks), 0.7)
    r = bootstrap_overall(d, values, n_draws=500, seed=3)
    assert np.allclose(r.draws, 0.7)
    assert np.allclose(r.ci, 0.7)
    assert np.allclose(r.point, 0.7)


def test_draw_weights_match_explicit_resampling():
    """W @ v equals eq. 3 computed from the resampled object lists one draw at a time."""
    d = paper_design(6)
    rng = np.random.default_rng(1)
    values = rng.random(d.n_tasks)
    counts = object_counts(d, 40, np.random.default_rng(7))
    fast = draw_weights(d, counts) @ values
    for b in range(40):
        source_means = []
        for source in d.sources:
            cond_means = []
            for ci, (s, _cond) in enumerate(d.cells):
                if s != source:
                    continue
                resampled = []
                for t in range(len(d.tasks)):
                    if d.task_cell[t] == ci:
                        resampled += [values[t]] * int(counts[b, d.task_object[t]])
                cond_means.append(np.mean(resampled))
            source_means.append(np.mean(cond_means))
        assert fast[b] == pytest.approx(np.mean(source_means), abs=1e-12)
    # each source draws exactly as many objects as it has
    for k in range(len(d.sources)):
        assert np.all(counts[:, d.object_source == k].sum(axis=1) == np.sum(d.object_source == k))


def test_bootstrap_keeps_partnet_conditions_paired():
    """System 1 succeeds on object o's no-reference task iff system 2 succeeds on its image task:
    with paired resampling every draw gives them the same Overall; unpaired it would not."""
    d = paper_design(20)
    wins = {3, 5, 8, 13, 17}
    s1 = sr_row(d, {PN_NR: wins})
    s2 = sr_row(d, {PN_IR: wins})
    r = bootstrap_overall(d, np.stack([s1, s2]), n_draws=2000, seed=0)
    assert np.array_equal(r.draws[:, 0], r.draws[:, 1])
    assert r.diff_ci(0, 1).tolist() == [0.0, 0.0]
    assert r.ci[1, 0] > r.ci[0, 0]  # yet the draws do vary


def test_bootstrap_variance_of_a_single_cell_mean():
    """One cell of n objects: the bootstrap variance of the mean is sigma^2 / n."""
    n = 25
    d = Design.from_tasks([TaskMeta(f"t{i}", "s", "none", f"o{i}") for i in range(n)])
    values = np.random.default_rng(0).random(n)
    r = bootstrap_overall(d, values[None], n_draws=10_000, seed=1)
    assert r.draws[:, 0].var() == pytest.approx(values.var() / n, rel=0.05)
    assert r.draws[:, 0].mean() == pytest.approx(values.mean(), abs=3 * np.sqrt(values.var() / n / 10_000))


def test_bootstrap_reproduces_the_paper_intervals_of_astra_and_qwen():
    """The per-object outcomes of Astra and Qwen are determined by Table 1 and the reference
    table's SR up/down counts; their intervals match Table A-3 up to one grid step
    (1/160 = 0.625 points, the resolution of eq. 3 on 20 objects) of Monte Carlo noise."""
    d = paper_design()
    astra = first_k(d, {PN_NR: 3, PN_IR: 8, IK: 13, AB: 11, FB: 18})  # SR up/down 5/0: nested
    qwen = sr_row(d, {PN_NR: {19}, AB: {0, 1}, FB: set(range(7))})  # SR up/down 0/1
    r = bootstrap_overall(d, np.stack([astra, qwen]), n_draws=10_000, seed=0)
    assert r.ci[:, 0] * 100 == pytest.approx([50.0, 68.125], abs=0.63)
    assert r.ci[:, 1] * 100 == pytest.approx([5.625, 18.125], abs=0.63)


def test_bootstrap_is_deterministic_for_a_seed():
    d = paper_design(4)
    v = np.random.default_rng(0).random((2, d.n_tasks))
    a = bootstrap_overall(d, v, n_draws=300, seed=11)
    b = bootstrap_overall(d, v, n_draws=300, seed=11)
    c = bootstrap_overall(d, v, n_draws=300, seed=12)
    assert np.array_equal(a.draws, b.draws)
    assert not np.array_equal(a.draws, c.draws)


def test_bootstrap_rejects_non_finite_values():
    d = paper_design(2)
    v = np.zeros((1, d.n_tasks))
    v[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        bootstrap_overall(d, v, n_draws=10)


def test_draw_weights_when_a_condition_is_not_drawn():
    """A source whose conditions cover different objects: a draw without any object of one
    condition gives the whole source weight to the other condition."""
    tasks = [TaskMeta("a", "s", "none", "o1"), TaskMeta("b", "s", "image", "o2")]
    d = Design.from_tasks(tasks)
    counts = np.array([[2, 0], [1, 1], [0, 2]])
    w = draw_weights(d, counts)
    assert w.tolist() == [[1.0, 0.0], [0.5, 0.5], [0.0, 1.0]]


# ---- randomization tests and Holm ------------------------------------------------------------


def test_holm_on_a_known_family():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted: 0.005*4=0.02, 0.01*3=0.03, 0.03*2=0.06, 0.04*1=0.04 -> running max 0.06
    assert holm(p).tolist() == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.6]).tolist() == pytest.approx([1.0, 1.0])
    assert holm([]).tolist() == []


def test_holm_matches_a_direct_implementation():
    rng = np.random.default_rng(5)
    for _ in range(20):
        p = rng.random(12) ** 3
        m = len(p)
        order = sorted(range(m), key=lambda i: p[i])
        expected = [0.0] * m
        running = 0.0
        for rank, i in enumerate(order):
            running = max(running, min(1.0, (m - rank) * p[i]))
            expected[i] = running
        assert holm(p).tolist() == pytest.approx(expected)


def test_holm_rejects_invalid_p():
    with pytest.raises(ValueError):
        holm([0.2, 1.5])


def test_add_one_p_values():
    # No difference at all: every relabelling ties, p = (1 + R) / (1 + R) = 1.
    assert randomization_pvalues(np.zeros((5, 1)), n_permutations=999).tolist() == [1.0]
    # 40 objects all pointing the same way: |T*| = |T_obs| needs all signs equal (2^-39),
    # so no draw reaches it and p is the add-one floor 1 / (1 + R).
    assert randomization_pvalues(np.ones((40, 1)), n_permutations=999).tolist() == [1 / 1000]


def test_randomization_p_matches_exact_enumeration():
    """Contributions (1, 2, 4, 0.5): the exact two-sided p is the share of the 16 sign patterns
    with |sum| >= 7.5, i.e. 2/16; more draws converge to it."""
    contrib = np.array([[1.0], [2.0], [4.0], [0.5]])
    exact = np.mean([abs(np.dot(s, contrib[:, 0])) >= 7.5 for s in itertools.product([-1, 1], repeat=4)])
    assert exact == 2 / 16
    r = 100_000
    p = randomization_pvalues(contrib, n_permutations=r, seed=2)[0]
    # add-one: (1 + hits) / (1 + R) with hits ~ Binomial(R, exact)
    assert p == pytest.approx((1 + exact * r) / (1 + r), abs=4 * np.sqrt(exact * (1 - exact) / r))


def test_labels_are_exchanged_jointly_within_objects():
    """Two tasks of one object with opposite differences cancel inside the object: the test
    statistic of that object is 0 whatever the relabelling."""
    tasks = [TaskMeta("n", "partnet", "none", "o1"), TaskMeta("i", "partnet", "image", "o1")]
    d = Design.from_tasks(tasks)
    contrib = object_contributions(d, np.array([[1.0, -1.0]]))
    assert contrib.tolist() == [[0.0]]
    # and a consistent difference on one object cannot be significant: p = 1
    contrib = object_contributions(d, np.array([[1.0, 1.0]]))
    assert randomization_pvalues(contrib, n_permutations=1000)[0] == 1.0


def test_pairwise_tests_at_full_counts_on_a_paper_sized_table():
    """8 systems x 100 tasks, 10,000 bootstrap draws and 100,000 relabellings (the paper's counts)."""
    d = paper_design()
    rng = np.random.default_rng(0)
    skill = np.array([0.9, 0.8, 0.6, 0.3, 0.2, 0.2, 0.15, 0.0])
    sr = (rng.random((8, d.n_tasks)) < skill[:, None]).astype(float)
    pa = np.clip(sr + rng.random((8, d.n_tasks)) * 0.3, 0, 1)
    sr[6] = sr[5]  # two identical systems
    counts = object_counts(d, 10_000, np.random.default_rng(0))
    w = draw_weights(d, counts)
    pairs = list(itertools.combinations(range(8), 2))
    tests = pairwise_tests(d, {"SR": sr, "PA": pa}, w, pairs=pairs, n_permutations=100_000, seed=0)
    assert len(tests) == 56
    by = {(t.a, t.b, t.metric): t for t in tests}
    assert by[(5, 6, "SR")].diff == 0.0 and by[(5, 6, "SR")].p == 1.0 and by[(5, 6, "SR")].p_holm == 1.0
    assert by[(0, 7, "SR")].p == 1 / 100_001
    assert by[(0, 7, "SR")].p_holm == pytest.approx(56 / 100_001)
    raw = np.array([t.p for t in tests])
    assert np.allclose([t.p_holm for t in tests], holm(raw))
    for t in tests:
        lo, hi = t.ci
        assert lo <= t.diff + 1e-12 and t.diff - 1e-12 <= hi
        v = sr if t.metric == "SR" else pa
        assert t.diff == pytest.approx(d.weights @ (v[t.a] - v[t.b]))


# ---- paired reference effects and weighted medians -------------------------------------------


def test_reference_effects_hand_computed():
    tasks = []
    for o in range(4):
        tasks += [TaskMeta(f"n{o}", "partnet", "none", f"o{o}"), TaskMeta(f"i{o}", "partnet", "image", f"o{o}")]
    tasks.append(TaskMeta("f", "fantastic_breaks", "none", "f0"))
    d = Design.from_tasks(tasks)
    # PA per object: none 0.5, 0.2, 1.0, 0.0; image 1.0, 0.2, 0.5, 0.4 -> diffs +0.5, 0, -0.5, +0.4
    pa = np.array([[0.5, 1.0, 0.2, 0.2, 1.0, 0.5, 0.0, 0.4, 0.3]])
    sr = np.array([[0, 1, 0, 0, 1, 0, 0, 0, 1.0]])
    eff = {e.metric: e for e in reference_effects(d, {"PA": pa, "SR": sr}, n_draws=2000, seed=0)}
    assert eff["PA"].diff == pytest.approx(0.1)
    assert (eff["PA"].up, eff["PA"].down) == (2, 1)
    assert (eff["SR"].up, eff["SR"].down) == (1, 1)
    assert eff["SR"].diff == 0.0
    assert eff["PA"].n_objects == 4
    lo, hi = eff["PA"].ci
    assert -0.5 <= lo <= 0.1 <= hi <= 0.5


def test_paired_object_bootstrap_of_identical_diffs():
    mean, ci = paired_object_bootstrap(np.full((2, 7), 0.25), n_draws=100)
    assert mean.tolist() == [0.25, 0.25] and np.allclose(ci, 0.25)


def test_weighted_median():
    rng = np.random.default_rng(0)
    for n in (1, 2, 5, 6):
        v = rng.random(n)
        assert weighted_median(v, np.ones(n)) == pytest.approx(np.median(v))
    assert weighted_median([1, 2, 3], [1, 1, 5]) == 3
    assert weighted_median([1, 2, 3], [3, 1, 1]) == 1
    assert weighted_median([np.nan, 2.0], [1, 1]) == 2.0
    assert np.isnan(weighted_median([], []))
    with pytest.raises(ValueError):
        weighted_median([1.0], [-1.0])
