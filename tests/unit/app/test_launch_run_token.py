"""The run's token stays a string where ROS reads a parameter value as YAML."""

from __future__ import annotations

import secrets

import pytest
import yaml

from stillframe.contract import run_token


@pytest.mark.parametrize("digits", ["12e4567890123456", "1234567890123456", "0000000000000000"])
def test_a_token_of_digits_is_still_a_string_to_yaml(monkeypatch: pytest.MonkeyPatch,
                                                    digits: str) -> None:
    """Bare, these hex draws read as numbers (inf, integers: as ROS read a launch's token and
    refused it as a string parameter); the token is no number and stays a string."""
    float(digits)
    monkeypatch.setattr(secrets, "token_hex", lambda n: digits)
    token = run_token.new_run_token()
    with pytest.raises(ValueError):
        float(token)
    assert yaml.safe_load(token) == token
