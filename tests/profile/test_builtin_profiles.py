"""Built-in profiles by name: what `-p NAME`, `profile = "NAME"`, `profile list` and
`profile init` do, and what they refuse."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.errors import ProfileError
from eskin_industrial.profile import builtin_profiles, find_profile, load_profile
from tests.helpers.paths import PROFILES


def test_every_checkout_profile_is_a_builtin_name() -> None:
    assert set(builtin_profiles()) == {p.stem for p in PROFILES.glob("*.toml")}
    for name in builtin_profiles():
        assert load_profile(name) == load_profile(PROFILES / f"{name}.toml")


def test_a_file_wins_over_a_builtin_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    own = (PROFILES / "paper-5x5.toml").read_text().replace('name = "paper-5x5"', 'name = "cell7-left"')
    (tmp_path / "paper-5x5").write_text(own)
    monkeypatch.chdir(tmp_path)
    assert load_profile("paper-5x5").name == "cell7-left"
    (tmp_path / "paper-5x5").unlink()
    assert load_profile("paper-5x5").name == "paper-5x5"  # no such file: the built-in one


def test_unknown_name_and_missing_path_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match=r"not a built-in profile \(built-in: hand-4x5, paper-5x5, strip-1x5\)"):
        find_profile("paper-6x6")
    with pytest.raises(ProfileError, match="cannot read profile"):
        load_profile(tmp_path / "sub" / "paper-5x5")  # a path with a folder stays a path
    with pytest.raises(ProfileError, match="paper-5x5.toml: cannot read profile"):
        load_profile("paper-5x5.toml", base=tmp_path)  # so does a file name


def test_bridge_config_names_builtin_profiles(tmp_path: Path) -> None:
    (tmp_path / "bridge.toml").write_text(
        '[plc]\nmode = "server"\nhost = "127.0.0.1"\nport = 1502\n'
        '[[node]]\nname = "left"\nprofile = "paper-5x5"\nsource = "scene"\nscene = "case2"\n')
    out = CliRunner().invoke(main, ["bridge", "--config", str(tmp_path / "bridge.toml"), "--check"])
    assert out.exit_code == 0, out.output
    assert "left" in out.output


def test_profile_init_copies_and_refuses_to_overwrite(tmp_path: Path) -> None:
    runner = CliRunner()
    target = tmp_path / "mine.toml"
    first = runner.invoke(main, ["profile", "init", "hand-4x5", "-o", str(target)])
    assert first.exit_code == 0, first.output
    assert target.read_text() == (PROFILES / "hand-4x5.toml").read_text()
    again = runner.invoke(main, ["profile", "init", "hand-4x5", "-o", str(target)])
    assert again.exit_code == 2 and "exists" in again.output
    unknown = runner.invoke(main, ["profile", "init", "nope", "-o", str(tmp_path / "x.toml")])
    assert unknown.exit_code == 2 and "not a built-in profile" in unknown.output


def test_examples_list_and_copy(tmp_path: Path) -> None:
    runner = CliRunner()
    listed = runner.invoke(main, ["examples"])
    assert listed.exit_code == 0
    assert {"bridge.toml", "hand-strips.toml", "eskin-bus-bridge.service"} <= {
        line.split()[0] for line in listed.output.splitlines()}
    copied = runner.invoke(main, ["examples", "-o", str(tmp_path / "cell")])
    assert copied.exit_code == 0, copied.output
    # The copy binds the example's cell interface, absent here: --check tries the listen
    # address (it says so), so the copy is checked as an integrator on a test bench would
    # check it, on loopback.
    strips = tmp_path / "cell" / "hand-strips.toml"
    refused = runner.invoke(main, ["bridge", "--config", str(strips), "--check"])
    assert refused.exit_code == 2 and "192.168.10.5" in refused.output
    strips.write_text(strips.read_text().replace('host = "192.168.10.5"', 'host = "127.0.0.1"'))
    checked = runner.invoke(main, ["bridge", "--config", str(strips), "--check"])
    assert checked.exit_code == 0, checked.output
    again = runner.invoke(main, ["examples", "-o", str(tmp_path / "cell")])
    assert again.exit_code == 2 and "exists" in again.output
