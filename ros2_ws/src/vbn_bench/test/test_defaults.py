"""One place for defaults: every signature and option reads landmark_db.defaults."""
from __future__ import annotations

import argparse
from dataclasses import FrozenInstanceError
import inspect

import pytest

from landmark_db.cli import decompose as decompose_cli
from landmark_db.decomposition import decompose
from landmark_db.decomposition.best import best_cover
from landmark_db.decomposition.exact import exact_cover
from landmark_db.defaults import DECOMPOSITION, POSE_SPACING, THESIS
from vbn_bench.decomposition.runner import BenchConfig
from vbn_bench.decomposition.scaling import run_scaling
from vbn_worlds.cli import simulate as simulate_cli


def test_thesis_parameters_are_section_8_2s() -> None:
    assert (THESIS.k, THESIS.rho, THESIS.sigma, THESIS.alpha) == (4, 1, 9, 0.85)
    assert (DECOMPOSITION.rho, DECOMPOSITION.sigma, DECOMPOSITION.alpha) == (0, 0, 0.85)
    assert POSE_SPACING == 0.5
    with pytest.raises(FrozenInstanceError):
        DECOMPOSITION.alpha = 0.5  # type: ignore[misc]


def _defaults(function: object) -> dict[str, object]:
    return {name: p.default for name, p in inspect.signature(function).parameters.items()}


def test_library_signatures_use_the_defaults() -> None:
    assert _defaults(decompose)['alpha'] == DECOMPOSITION.alpha
    assert _defaults(decompose)['rho'] == DECOMPOSITION.rho
    assert _defaults(decompose)['sigma'] == DECOMPOSITION.sigma
    assert _defaults(best_cover)['alpha'] == DECOMPOSITION.alpha
    assert _defaults(best_cover)['time_limit'] == DECOMPOSITION.best_time_limit
    assert _defaults(exact_cover)['time_limit'] == DECOMPOSITION.exact_time_limit
    scaling = _defaults(run_scaling)
    assert (scaling['k'], scaling['rho'], scaling['sigma'], scaling['alpha']) == \
        (THESIS.k, THESIS.rho, THESIS.sigma, THESIS.alpha)
    bench = BenchConfig()
    assert (bench.k, bench.rho, bench.sigma, bench.alpha, bench.spacing) == \
        (THESIS.k, THESIS.rho, THESIS.sigma, THESIS.alpha, POSE_SPACING)


def _parse(module: object, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='vbn')
    module.register(parser.add_subparsers(dest='command'))  # type: ignore[attr-defined]
    return parser.parse_args(argv)


def test_command_line_options_use_the_defaults() -> None:
    args = _parse(decompose_cli, ['decompose', 'w.json', '--algorithm', 'C', '--k', '3',
                                  '--out', 'd.json'])
    assert (args.rho, args.sigma, args.alpha, args.seed) == \
        (DECOMPOSITION.rho, DECOMPOSITION.sigma, DECOMPOSITION.alpha, DECOMPOSITION.seed)
    args = _parse(simulate_cli, ['simulate', '--setting', '1', '--seed', '0', '--out', 'w.json'])
    assert args.spacing == POSE_SPACING
