"""``--set NAME=VALUE``: one parser for vbn build, bench-build and localize."""
from __future__ import annotations

import pytest

from vbn_common.cli.assignments import parse_assignments
from vbn_common.errors import VbnError


def test_values_are_yaml_scalars_and_names_are_stripped() -> None:
    assert parse_assignments([' k = 8', 'ratio=0.8', 'flag=true', 'ratio2=null',
                              'algorithm=best', 'note=a: b: c']) == {
        'k': 8, 'ratio': 0.8, 'flag': True, 'ratio2': None, 'algorithm': 'best',
        'note': 'a: b: c'}
    assert parse_assignments([]) == {}


@pytest.mark.parametrize('item', ['k', '=3', ' =3'])
def test_an_item_without_a_name_or_an_equals_sign_is_one_line(item: str) -> None:
    with pytest.raises(VbnError, match='--set wants NAME=VALUE'):
        parse_assignments([item])
