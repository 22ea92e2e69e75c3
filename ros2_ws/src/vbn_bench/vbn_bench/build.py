"""Measurements of the builder: time per step, peak memory, size, and the k x rho sweep.

``vbn bench-build`` drives these. Each build runs in a process of its own (``vbn build``
imported and started in a fresh interpreter, :mod:`vbn_bench.commands`) so that its peak
memory is its own: :class:`MemorySampler` polls the resident set of
the process and all its descendants (the SIFT workers) from ``/proc`` every 50 ms and
keeps the largest sum. The size comparison is against the full unpruned feature
database the thesis argues against: every SIFT descriptor (128 bytes as uint8) and
keypoint (two float32) of every image.

:func:`sweep` decomposes one built world for every (k, rho), as the thesis's Figures
8.8 to 8.15 do for its 6 m x 3 m room, and reports regions and coverage.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import json
import os
from pathlib import Path
import threading
import time
from typing import Any

import numpy as np

from landmark_db.decomposition import decompose, service
from landmark_db.world import WorldInstance

__all__ = ['BuildRun', 'FULL_FEATURE_BYTES', 'MemorySampler', 'SweepPoint', 'run_build',
           'sweep']

#: Bytes per feature of the full unpruned feature database: descriptor + keypoint.
FULL_FEATURE_BYTES = 128 + 8


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        current = todo.pop()
        out.append(current)
        try:
            for task in os.listdir(f'/proc/{current}/task'):
                with open(f'/proc/{current}/task/{task}/children') as handle:
                    todo.extend(int(c) for c in handle.read().split())
        except OSError:
            continue
    return out


def _rss_bytes(pid: int) -> int:
    try:
        with open(f'/proc/{pid}/statm') as handle:
            return int(handle.read().split()[1]) * os.sysconf('SC_PAGE_SIZE')
    except (OSError, IndexError, ValueError):
        return 0


class MemorySampler:
    """Largest summed resident set of a process tree, sampled in a thread.

    Args:
        pid: The root process.
        period_s: Sampling period.
    """

    def __init__(self, pid: int, period_s: float = 0.05) -> None:
        self.pid = pid
        self.period_s = period_s
        self.peak_bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            total = sum(_rss_bytes(p) for p in _descendants(self.pid))
            self.peak_bytes = max(self.peak_bytes, total)
            self._stop.wait(self.period_s)

    def __enter__(self) -> MemorySampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        self._thread.join()


@dataclass
class BuildRun:
    """One measured build.

    Attributes:
        bag: The bag.
        seconds: Wall time of the whole command.
        peak_bytes: Peak resident memory of the process tree.
        db_bytes: Database file size.
        full_bytes: Size of the full unpruned feature database of the same bag.
        summary: ``summary.json`` of the build (steps' seconds and counts).
        returncode: The command's exit code.
        output: What it printed (stderr and stdout).
    """

    bag: str
    seconds: float
    peak_bytes: int
    db_bytes: int
    full_bytes: int
    summary: dict[str, Any]
    returncode: int
    output: str

    def as_dict(self) -> dict[str, Any]:
        """JSON-able record (without the output)."""
        return {'bag': self.bag, 'seconds': round(self.seconds, 2),
                'peak_mb': round(self.peak_bytes / 2**20, 1),
                'db_mb': round(self.db_bytes / 1e6, 3),
                'full_feature_db_mb': round(self.full_bytes / 1e6, 2),
                'size_ratio': round(self.full_bytes / max(self.db_bytes, 1), 1),
                'returncode': self.returncode, 'steps': self.summary.get('seconds', {}),
                'counts': self.summary.get('counts', {})}


def run_build(bag: str | Path, out_dir: Path, extra_args: Sequence[str] = ()) -> BuildRun:
    """Run ``vbn build`` on a bag in a process of its own and measure it."""
    from vbn_bench.commands import start_isolated

    name = Path(bag).name
    db = out_dir / f'{name}.db'
    report = out_dir / f'{name}_report'
    log = out_dir / f'{name}_build.log'
    args = ['build', str(bag), '--db', str(db), '--report', str(report), '--quiet',
            *extra_args]
    start = time.perf_counter()
    proc = start_isolated(args, log)
    try:
        with MemorySampler(proc.pid) as sampler:
            proc.join()
    except BaseException:
        proc.terminate()
        proc.join()
        raise
    seconds = time.perf_counter() - start
    summary: dict[str, Any] = {}
    if proc.exitcode == 0 and (report / 'summary.json').is_file():
        summary = json.loads((report / 'summary.json').read_text())
    features = int(summary.get('counts', {}).get('features', {}).get('features', 0))
    return BuildRun(str(bag), seconds, sampler.peak_bytes,
                    db.stat().st_size if db.is_file() else 0, features * FULL_FEATURE_BYTES,
                    summary, proc.exitcode, log.read_text(errors='replace'))


@dataclass(frozen=True)
class SweepPoint:
    """One decomposition of the sweep.

    Attributes:
        k: Features per landmark.
        rho: Overlap radius.
        regions: Number of regions.
        coverable: k-coverable poses (rho-reduced, :mod:`landmark_db.decomposition.service`).
        covered: Of those, the poses served (N_rho(v) inside one region).
        mean_region_poses: Mean region size.
        seconds: Decomposition time.
        decomposition: The regions themselves (for figures).
    """

    k: int
    rho: int
    regions: int
    coverable: int
    covered: int
    mean_region_poses: float
    seconds: float
    decomposition: Any

    @property
    def coverage(self) -> float:
        """Served share of the k-coverable poses."""
        return self.covered / self.coverable if self.coverable else 0.0


def sweep(world: WorldInstance, ks: Sequence[int], rhos: Sequence[int], algorithm: str,
          sigma: int, seed: int = 0) -> list[SweepPoint]:
    """Decompose ``world`` for every (k, rho) pair."""
    out = []
    for k in ks:
        for rho in rhos:
            result = decompose(world, algorithm, k, rho, sigma, rng=seed)
            served = service(world, [region.poses for region in result.regions], k, rho)
            sizes = [r.poses.size for r in result.regions]
            out.append(SweepPoint(k, rho, len(result.regions), served.k_coverable,
                                  served.served, float(np.mean(sizes)) if sizes else 0.0,
                                  result.seconds, result))
    return out
