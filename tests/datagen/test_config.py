"""Bad datagen configs are rejected with one line that names the field; the CLI says so too."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from diathermy.cli import main
from diathermy.datagen import DatagenConfig, DatagenConfigError, config_from_dict, load_config


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"p_min_pa": 2e5, "p_max_pa": 1e5}, "p_max_pa"),
        ({"p_min_pa": 5e4}, "p_min_pa"),
        ({"p_max_pa": float("nan")}, "p_max_pa"),
        ({"n_steps": 0}, "n_steps"),
        ({"n_scenarios": -1}, "n_scenarios"),
        ({"grid": [5, 5, 9], "n_scenarios": 65}, "n_scenarios"),
        ({"grid": [2, 5, 9]}, "grid"),
        ({"perturbation": 1.5}, "perturbation"),
        ({"seed": -3}, "seed"),
        ({"dtype": "float16"}, "dtype"),
        ({"workers": 0}, "workers"),
        ({"material": {"poisson_ratio": 0.6}}, "poisson_ratio"),
        ({"level_set": {"cfl": 2}}, "level_set.cfl"),
        ({"pressure_range": [1, 2]}, "pressure_range"),
    ],
)
def test_bad_fields_are_named_in_one_line(data: dict, field: str) -> None:
    with pytest.raises(DatagenConfigError) as err:
        config_from_dict(data)
    message = str(err.value)
    assert "\n" not in message and field in message and message.startswith("datagen config:")


@given(lo=st.floats(1.01325e5, 1e7), hi=st.floats(1.01325e5, 1e7))
def test_the_pressure_range_is_accepted_exactly_when_ordered(lo: float, hi: float) -> None:
    if hi > lo:
        assert config_from_dict({"p_min_pa": lo, "p_max_pa": hi}).p_max_pa == hi
    else:
        with pytest.raises(DatagenConfigError, match="p_max_pa"):
            config_from_dict({"p_min_pa": lo, "p_max_pa": hi})


def test_defaults_cover_the_built_in_scenes() -> None:
    c = DatagenConfig()
    assert c.p_min_pa == c.material.p_atm_pa and c.p_max_pa >= 8.3e5  # PHYSICS.md 1: ~830 kPa
    assert c.perturbation == 0.05 and c.n_scenarios * c.n_steps == 200_000


def test_files_round_trip_and_bad_files_are_one_line(tmp_path: Path) -> None:
    good = tmp_path / "c.yaml"
    good.write_text("grid: [5, 5, 9]\nn_scenarios: 2\nn_steps: 3\nseed: 4\n")
    assert load_config(good).grid == (5, 5, 9)
    as_json = tmp_path / "c.json"
    as_json.write_text(json.dumps(load_config(good).model_dump(mode="json")))
    assert load_config(as_json) == load_config(good)
    for name, text, needle in (
        ("broken.json", "{", "not valid"),
        ("list.yaml", "- 1\n- 2\n", "mapping"),
        ("typo.yaml", "n_step: 3\n", "n_step"),
    ):
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(DatagenConfigError, match=needle) as err:
            load_config(path)
        assert "\n" not in str(err.value)
    with pytest.raises(DatagenConfigError, match="cannot read"):
        load_config(tmp_path / "absent.yaml")


def test_cli_reports_config_and_file_errors_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("p_min_pa: 3e5\np_max_pa: 2e5\n")
    assert main(["datagen", str(bad), "--out", str(tmp_path / "d.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("diathermy: error: datagen config: field 'p_max_pa'")
    assert "\n" not in err
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"junk")
    good = tmp_path / "good.yaml"
    good.write_text("grid: [5, 5, 9]\nn_scenarios: 1\nn_steps: 1\n")
    assert main(["datagen", str(good), "--out", str(junk), "--resume", "--quiet"]) == 2
    assert "not a readable HDF5 file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["datagen", str(good), "--out", str(junk), "--workers", "0"])
