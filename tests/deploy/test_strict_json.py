"""The strict JSON parser of the wire protocol's JSON payloads."""

import pytest

from virl_quad.deploy.strict_json import loads_strict


def test_plain_json_parses_as_json_loads():
    assert loads_strict('{"a": [1, 2.5, "x"], "b": {"c": null}}') == {"a": [1, 2.5, "x"], "b": {"c": None}}


@pytest.mark.parametrize("text", ['{"x": NaN}', '{"x": -Infinity}', '{"x": 1e400}', '[1e309]',
                                  '{"a": 1, "a": 2}', '{"o": {"k": 1, "k": 1}}'])
def test_refuses_what_parsers_read_differently(text):
    with pytest.raises(ValueError):
        loads_strict(text)
