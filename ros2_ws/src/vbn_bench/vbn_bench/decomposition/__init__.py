"""The thesis's synthetic decomposition experiment (Section 8.2), rerun and extended.

:mod:`.runner` simulates worlds and runs every algorithm with the validator,
:mod:`.report` averages and prints Tables 8.2-8.4 beside the thesis's
(:mod:`.reference`), :mod:`.figures` draws Figure 8.3 and decomposition pictures,
:mod:`.calibration` fits the feature density to Table 8.4 and :mod:`.scaling` times
the algorithms on worlds of up to 100,000 poses. ``vbn bench-decomposition`` is the
command line.
"""
from __future__ import annotations

from vbn_bench.decomposition.runner import BenchConfig, RunRecord, run_benchmark

__all__ = ['BenchConfig', 'RunRecord', 'run_benchmark']
