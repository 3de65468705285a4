"""Issue 26, item 2b: every key of every section the schema knows, set on every architecture's
shipped example to another valid value, either changes the result of a short run (a metric
or a time series) or is refused (exit 2) as doing nothing for that vehicle."""

from __future__ import annotations

from pathlib import Path

import pytest
from tests.keys_helpers import EXAMPLES, SHIPPED, example_data, load, probe, section_keys

from hevsim import config as C
from hevsim.cli import main

NOT_PERTURBED: dict[str, str] = {
    "powertrain.architecture": "selects the configuration type itself (another value is another schema)",
    "simulation.cycle": "the default cycle: test_default_cycle_key_changes_the_run below",
}
"""Keys this test does not perturb, and why."""


def command_specific(key: str) -> str | None:
    """The command that reads ``key`` when it is not ``simulate`` (hevsim.config.COMMAND_KEYS)."""
    return C.COMMAND_KEYS.get(key) or C.COMMAND_KEYS.get(f"{key.partition('.')[0]}.*")


def _skip(key: str) -> bool:
    return key in NOT_PERTURBED or command_specific(key) is not None


@pytest.mark.parametrize("name", SHIPPED)
def test_every_key_changes_the_result_or_is_refused(name: str) -> None:
    cfg = load(example_data(name), name)
    verdicts = probe(name, skip=_skip)
    fields = {key: f for key, f, _ in section_keys(type(cfg))}
    # a choice whose every other value the schema refuses for this vehicle (exit 2: e.g. the
    # parallel HEV's engine must be a map, the one driver kind, the one controller of a BEV)
    only_one = {k for k, f in fields.items() if "choices" in f.metadata}
    silent = {
        key: v
        for key, v in verdicts.items()
        if not (v == "changes" or v.startswith("refused:"))
        and not (key in only_one and v == "no valid value")
    }
    assert not silent, f"{name}: keys that neither change the run nor are refused: {silent}"
    refused = [v for v in verdicts.values() if v.startswith("refused:")]
    for msg in refused:
        assert "does nothing for a" in msg and "key '" in msg


@pytest.mark.parametrize("name", SHIPPED)
def test_default_cycle_key_changes_the_run(name: str) -> None:
    from hevsim.sim.simulator import simulate

    data = example_data(name)
    a = simulate(load({**data, "simulation": {**data.get("simulation", {}), "cycle": "nycc"}}, name))
    b = simulate(load({**data, "simulation": {**data.get("simulation", {}), "cycle": "hwfet"}}, name))
    assert a.value("distance_mi") != b.value("distance_mi")


def test_command_specific_keys_name_their_command() -> None:
    for key, why in C.COMMAND_KEYS.items():
        assert why.startswith("hevsim "), key


@pytest.mark.parametrize(
    ("example", "section", "key", "value", "label"),
    [
        ("conventional_sedan", "controller", "soc_low", 0.5, "conventional vehicle"),
        ("conventional_sedan", "simulation", "soc_initial", 0.5, "conventional vehicle"),
        ("bev", "brakes", "max_decel_mps2", 7.0, "battery-electric vehicle"),
        ("parallel_hev", "motor", "data", "honda_pm49", "parallel HEV"),
        ("bev", "genset", "kind", "engine", "battery-electric vehicle"),
        ("series_hev", "alternator", "efficiency", 0.5, "series HEV"),
    ],
)
def test_cli_refuses_a_key_that_does_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], example: str, section: str, key: str,
    value: object, label: str,
) -> None:  # fmt: skip
    text = (EXAMPLES / f"{example}.toml").read_text(encoding="utf-8")
    literal = f'"{value}"' if isinstance(value, str) else repr(value)
    if f"[{section}]" in text:
        text = text.replace(f"[{section}]", f"[{section}]\n{key} = {literal}", 1)
    else:
        text += f"\n[{section}]\n{key} = {literal}\n"
    cfg = tmp_path / f"{example}.toml"
    cfg.write_text(text, encoding="utf-8")
    rc = main(["simulate", str(cfg), "--cycle", "udds", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"key '{section}.{key}' does nothing for a {label}" in err
    assert "Traceback" not in err and not (tmp_path / "out").exists()
