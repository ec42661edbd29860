"""Shared benchmark runner: ours versus the peer, side by side, in one process.

A benchmark file ``benchmarks/bench_<area>.py`` defines ``cases(quick: bool)``
returning a list of :class:`Case`. Inputs are built *before* the case is
returned, so the timed closures only run the operation. Each case is timed with
:class:`torch.utils.benchmark.Timer` (``blocked_autorange``, median and IQR) at
each thread count, ours and the peer in alternating blocks, and the median
ratio ours / peer is reported. NumPy/BLAS threads are limited with threadpoolctl when it
is present, Open3D's (a TBB pool threadpoolctl does not see) with
``open3d.utility.set_max_threads`` when Open3D is loaded.
"""

from __future__ import annotations

import contextlib
import json
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch
import torch.utils.benchmark as tbench

__all__ = ["Case", "Measurement", "time_fn", "run_case", "metadata"]


@dataclass
class Case:
    """One comparison.

    Attributes:
        name: what is measured, e.g. ``"transform_points (64,16384,2) f32 fwd"``.
        ours: zero-argument callable running our op (inputs prebuilt).
        peer: zero-argument callable running the peer, or ``None`` (report only).
        peer_name: e.g. ``"kornia 0.9.0"``.
        target: the ratio ours/peer we must stay at or under (``None``: reported only).
        peer_scale: multiply the peer time by this (extrapolating a loop run on a subset).
        threads: thread counts to time at.
        target_threads: the thread counts ``target`` applies to (None: all); rows at the
            other counts are reported without a target.
        extra: free-form numbers to report (errors, peak memory, points/s, ...).
        sync: synchronize CUDA inside the timed region.
        once: ``ours`` and ``peer`` each run once and time themselves (a run of minutes,
            usually in a fresh process that also measures its peak memory): they return a
            dict with ``"s"``, the seconds, and any other numbers, reported in the notes
            with an ``ours_`` or ``peer_`` prefix. No warm-up, no blocks.
    """

    name: str
    ours: Callable[[], object]
    peer: Callable[[], object] | None = None
    peer_name: str = ""
    target: float | None = None
    peer_scale: float = 1.0
    threads: tuple[int, ...] = (1, 2)
    target_threads: tuple[int, ...] | None = None
    extra: dict = field(default_factory=dict)
    sync: bool = False
    once: bool = False


@dataclass
class Measurement:
    case: str
    threads: int
    ours_ms: float
    ours_iqr_ms: float
    peer_ms: float | None
    peer_iqr_ms: float | None
    peer_name: str
    ratio: float | None
    target: float | None
    passed: bool | None
    extra: dict

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@contextlib.contextmanager
def _limit_threads(n: int):
    """torch, the BLAS/OpenMP pools (threadpoolctl) and Open3D (its own TBB pool, which
    threadpoolctl does not see) at ``n`` threads."""
    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    o3d = sys.modules.get("open3d")
    o3d_limit = getattr(getattr(o3d, "utility", None), "set_max_threads", None)
    if o3d_limit is not None:
        o3d_limit(n)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        threadpool_limits = None
    try:
        if threadpool_limits is None:
            yield
        else:
            with threadpool_limits(limits=n):
                yield
    finally:
        torch.set_num_threads(previous)
        if o3d_limit is not None:
            o3d_limit(0)  # 0: Open3D's default (no limit)


def time_fn(fn: Callable[[], object], threads: int, min_run_time: float, sync: bool = False):
    """Median and IQR of ``fn()`` in seconds, at ``threads`` threads."""
    if sync and torch.cuda.is_available():

        def stmt():
            fn()
            torch.cuda.synchronize()
    else:
        stmt = fn
    with _limit_threads(threads):
        timer = tbench.Timer(stmt="stmt()", globals={"stmt": stmt}, num_threads=threads)
        m = timer.blocked_autorange(min_run_time=min_run_time)
    return m.median, m.iqr


def run_case(case: Case, min_run_time: float = 0.5, rounds: int = 5) -> list[Measurement]:
    """Time ``case`` at each of its thread counts; one Measurement per count.

    Ours and the peer are timed in alternating short blocks (``rounds`` of each),
    so a change in machine load hits both; the reported times are the medians of
    the per-block medians and the ratio is the median of the per-round ratios.
    """
    import statistics

    if case.once:
        return [_run_once(case, n) for n in case.threads]
    out = []
    block = min_run_time / rounds
    for n in case.threads:
        case.ours()  # warm-up (allocators, lazy init)
        if case.peer is not None:
            case.peer()
        ours_t, ours_q, peer_t, peer_q, ratios = [], [], [], [], []
        for _ in range(rounds):
            med, iqr = time_fn(case.ours, n, block, case.sync)
            ours_t.append(med)
            ours_q.append(iqr)
            if case.peer is not None:
                pmed, piqr = time_fn(case.peer, n, block, case.sync)
                peer_t.append(pmed * case.peer_scale)
                peer_q.append(piqr * case.peer_scale)
                ratios.append(med / peer_t[-1])
        ours, ours_iqr = statistics.median(ours_t), statistics.median(ours_q)
        peer = peer_iqr = ratio = None
        if ratios:
            peer, peer_iqr = statistics.median(peer_t), statistics.median(peer_q)
            ratio = statistics.median(ratios)
        target = _target(case, n)
        passed = None if (ratio is None or target is None) else ratio <= target
        out.append(
            Measurement(
                case=case.name,
                threads=n,
                ours_ms=ours * 1e3,
                ours_iqr_ms=ours_iqr * 1e3,
                peer_ms=None if peer is None else peer * 1e3,
                peer_iqr_ms=None if peer_iqr is None else peer_iqr * 1e3,
                peer_name=case.peer_name,
                ratio=ratio,
                target=target,
                passed=passed,
                extra=dict(case.extra),
            )
        )
    return out


def _run_once(case: Case, threads: int) -> Measurement:
    """One self-timed call of ours and of the peer (see ``Case.once``)."""
    with _limit_threads(threads):
        ours = dict(case.ours())
        peer = None if case.peer is None else dict(case.peer())
    extra = dict(case.extra)
    extra.update({f"ours_{k}": v for k, v in ours.items() if k != "s"})
    ratio = None
    if peer is not None:
        extra.update({f"peer_{k}": v for k, v in peer.items() if k != "s"})
        ratio = ours["s"] / (peer["s"] * case.peer_scale)
    target = _target(case, threads)
    passed = None if (ratio is None or target is None) else ratio <= target
    return Measurement(
        case=case.name, threads=threads, ours_ms=ours["s"] * 1e3, ours_iqr_ms=0.0,
        peer_ms=None if peer is None else peer["s"] * case.peer_scale * 1e3,
        peer_iqr_ms=None if peer is None else 0.0, peer_name=case.peer_name, ratio=ratio,
        target=target, passed=passed, extra=extra,
    )


def _target(case: Case, threads: int) -> float | None:
    """The case's target at ``threads`` threads."""
    if case.target_threads is not None and threads not in case.target_threads:
        return None
    return case.target


def metadata() -> dict:
    """Versions, machine and time, stored with every result file."""
    import numpy

    meta = {
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": numpy.__version__,
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": __import__("os").cpu_count(),
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }
    for mod in ("kornia", "scipy", "skimage", "trimesh", "bezier", "cv2", "pymeshlab", "mcubes"):
        try:
            meta[mod] = __import__(mod).__version__
        except Exception:  # noqa: BLE001 - a missing peer is recorded as None
            meta[mod] = None
    return json.loads(json.dumps(meta, default=str))
