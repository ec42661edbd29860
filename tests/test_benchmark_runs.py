"""The benchmark runner's combination of repeated runs (``--repeat``)."""

from __future__ import annotations

from benchmarks.harness import Measurement
from benchmarks.run import median_of_runs


def _m(case: str, ratio: float | None, ours: float, peer: str = "peer") -> Measurement:
    return Measurement(case, 1, ours, 0.0, None if ratio is None else 1.0, None, peer,
                       ratio, None, None, {"k": 1})


def test_median_run_per_row_keeps_its_times_and_lists_every_ratio():
    runs = [[_m("a", 1.0, 10.0), _m("b", None, 5.0)],
            [_m("a", 3.0, 30.0), _m("b", None, 6.0)],
            [_m("a", 2.0, 20.0), _m("b", None, 7.0)]]
    a, b = median_of_runs(runs)
    assert (a.case, a.ratio, a.ours_ms) == ("a", 2.0, 20.0)
    assert a.extra == {"k": 1, "ratio_runs": [1.0, 3.0, 2.0]}
    assert (b.case, b.ours_ms) == ("b", 5.0)  # no ratio to order by: the first run
    assert median_of_runs(runs[:1])[0].extra == {"k": 1}  # one run: unchanged


def test_rows_of_one_case_against_several_peers_stay_apart():
    rows = median_of_runs([[_m("a", 1.0, 10.0, "p1"), _m("a", 2.0, 10.0, "p2")]])
    assert [(m.peer_name, m.ratio) for m in rows] == [("p1", 1.0), ("p2", 2.0)]


def test_a_target_holds_at_its_thread_counts_only():
    from benchmarks.harness import Case, run_case

    case = Case("noop", lambda: None, lambda: None, "noop", target=1e9, threads=(1, 2),
                target_threads=(1,))
    one, two = run_case(case, min_run_time=0.01, rounds=1)
    assert (one.threads, one.target, one.passed) == (1, 1e9, True)
    assert (two.threads, two.target, two.passed) == (2, None, None)
