"""``eskin-bus profile tune``: a method's thresholds taught from the user's own holds
(the rule: ``evaluation/teach.py``; docs/profiles.md, *Teach-in*)."""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path
from typing import Any

import click

from ..errors import InputFormatError, OutputFileError, ProfileError
from ..profile import Profile, builtin_profiles, load_profile
from .common import check_output, complete_profile, writing

#: What the rule's run over the project's slides is reported as.
_DELAY = "delay median {:.0f} ms, p90 {:.0f} ms"


@click.command()
@click.argument("profile_path", metavar="PROFILE", type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.argument("recordings", nargs=-1, metavar="RECORDING...", type=click.Path(dir_okay=False))
@click.option("--moves", multiple=True, type=click.Path(dir_okay=False), metavar="RECORDING",
              help="A recording of moves (carried, squeezed, swung; nothing slid): counts as holding too. Repeatable.")
@click.option("--slides", multiple=True, type=click.Path(dir_okay=False), metavar="RECORDING",
              help="A recording of slides, to see them still found (default: the project's own slide scenes, "
                   "with the holds' noise and jitter). Repeatable.")
@click.option("-m", "--method", default=None, help="The method to tune (default: the profile's).")
@click.option("--false-alarms-per-hour", "per_hour", type=click.FloatRange(min=0.01, max=3600.0), default=1.0,
              show_default=True, help="The target on the holds.")
@click.option("--write", is_flag=True, help="Write the new thresholds into PROFILE itself.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Where to write the tuned profile (default: PROFILE's name with .tuned.toml, here).")
def tune(profile_path: str, recordings: tuple[str, ...], moves: tuple[str, ...], slides: tuple[str, ...],
         method: str | None, per_hour: float, write: bool, output: str | None) -> None:
    """Set the method's thresholds from RECORDINGs of the user's own stable holds (each
    one's whole length counts as holding), for at most the target's false alarms on
    them; write them into a copy of PROFILE (or it, with --write) and print what
    changed and the detection delay to expect on slides."""
    from ..evaluation import teach as tt
    from ..methods import get_method

    if not recordings and not moves:
        raise click.UsageError("give at least one RECORDING of stable holds (or --moves RECORDING)")
    if write and output is not None:
        raise click.UsageError("--write writes PROFILE itself, -o another file: give one of them")
    profile = load_profile(profile_path)
    name = method or profile.detector.method
    try:
        chosen = get_method(name)
    except KeyError as exc:
        raise click.BadParameter(str(exc.args[0]), param_hint="-m/--method") from None
    if not chosen.tunable:
        raise click.BadParameter(f"method {name} declares no threshold to teach; methods that do: "
                                 f"{', '.join(_tunable_methods())}", param_hint="-m/--method")
    source = Path(profile.source)
    target = _target(profile_path, source, write, output)
    check_output(str(target), "-o")
    holds, rate = _read(profile, (*recordings, *moves))
    hours = sum(h.seconds for h in holds) / 3600.0
    need = tt.min_hold_hours(per_hour)
    if hours < need:
        raise InputFormatError(f"{len(holds)} recording(s) hold {_minutes(hours)} in all: too short to say "
                               f"{per_hour:g} false alarm(s) an hour; record {_minutes(need)} of holding at least")
    x, y = profile.coordinates_mm
    settings = profile.detector
    taught = tt.teach(name, settings, x, y, rate, holds, per_hour)
    seen = tt.sensor_noise(holds, x, y)
    click.echo(f"{profile.name}: method {taught.method}, {len(holds)} recording(s), {_minutes(hours)} of holding at "
               f"{rate:g} Hz; target {per_hour:g} false alarm(s) an hour (at most {taught.allowed} on these holds)")
    rows = [("setting", "old", "new", "")]
    for c in taught.changes:
        note = f"its bound (the rule asked {c.wanted:g})" if c.wanted is not None else ""
        rows.append((f"[{taught.section}] {c.key}", f"{c.old:g}", f"{c.new:g}", note))
    width = [max(len(r[i]) for r in rows) for i in range(3)]
    for r in rows:
        click.echo(f"  {r[0]:<{width[0]}}  {r[1]:>{width[1]}}  {r[2]:>{width[2]}}  {r[3]}".rstrip())
    click.echo(f"false alarms an hour on the holds: {taught.before / hours:.1f} before ({taught.before}), "
               f"{taught.after / hours:.1f} after ({taught.after})")
    for line in _slides(name, settings, taught.settings, profile, rate, seen, slides):
        click.echo(line)
    if not taught.met:
        click.echo(f"eskin-bus: warning: the holds still raise {taught.after} false alarm(s) with every threshold "
                   f"at its bound: this method cannot meet the target on this sensor", err=True)
    text = set_keys(source.read_text(encoding="utf-8"), taught.section,
                    {c.key: c.new for c in taught.changes}, str(target))
    with writing(str(target), "-o"):
        target.write_text(text, encoding="utf-8")
    try:
        load_profile(target)
    except ProfileError as exc:  # (the file was valid and only numbers in bounds were set: a bug if it shows)
        raise OutputFileError(f"{target}: written, but it no longer loads: {exc}") from None
    click.echo(f"{target}: [{taught.section}] written; check it with `eskin-bus profile show {target}`")


def _tunable_methods() -> list[str]:
    from ..methods import all_methods

    return [n for n, m in all_methods().items() if m.tunable]


def _target(profile_path: str, source: Path, write: bool, output: str | None) -> Path:
    if write:
        if source.resolve() in {p.resolve() for p in builtin_profiles().values()}:
            raise click.UsageError(f"{profile_path} is a built-in profile, which --write cannot change: give -o FILE")
        return source
    return Path(output) if output is not None else Path(f"{source.stem}.tuned.toml")


def _read(profile: Profile, paths: tuple[str, ...]) -> tuple[list[Any], float]:
    """Each recording calibrated by the profile (its checks: taxels, rate), as holds;
    and the rate they share."""
    from ..evaluation.teach import Hold

    holds, rates = [], []
    for path in paths:
        found = _calibrated(profile, path)
        assert found.t is not None and found.forces is not None  # (a recording's are kept)
        holds.append(Hold(found.name, found.t, found.forces))
        rates.append(found.rate_hz)
    if max(rates) > 1.02 * min(rates):
        raise InputFormatError(f"the recordings' rates differ ({min(rates):g} to {max(rates):g} Hz): teach from "
                               f"recordings at one rate")
    return holds, float(sorted(rates)[len(rates) // 2])


def _calibrated(profile: Profile, path: str) -> Any:
    """A recording read and checked as ``detect`` reads it (the paper's batch run: cheap)."""
    import dataclasses

    from ..offline import detect_recording

    quick = dataclasses.replace(profile, detector=dataclasses.replace(profile.detector, method="paper"))
    return detect_recording(quick, path, method="paper")


def _slides(name: str, before: Any, after: Any, profile: Profile, rate: float, seen: Any,
            slides: tuple[str, ...]) -> list[str]:
    from ..evaluation import teach as tt

    if slides:
        return _given_slides(name, before, after, profile, slides)
    scenes = tt.slide_scenes(profile.layout.rows, profile.layout.cols)
    if not scenes:
        return [f"slides: no built-in slide scene has a {profile.layout.rows}x{profile.layout.cols} array; "
                f"give --slides RECORDING to see them found"]
    out = []
    for label, settings in (("before", before), ("after", after)):
        s = tt.slide_score(name, settings, scenes, rate, seen)
        delay = _DELAY.format(s.delay_percentile(50) * 1e3, s.delay_percentile(90) * 1e3) if s.delays_s else "no delay"
        out.append(f"slides {label}: {s.found} of {s.events} found, {delay}; {s.false_alarms} false alarm(s) "
                   f"in their {_minutes(s.holding_s / 3600.0)} of holding")
    return [f"slides: {', '.join(scenes)}, 2 seeds each, through the holds' noise ({seen.noise_n:.3g} N) and "
            f"jitter ({seen.jitter_mm:.3g} mm)", *out]


def _given_slides(name: str, before: Any, after: Any, profile: Profile, slides: tuple[str, ...]) -> list[str]:
    """Each slide recording's slips at the old settings and the new (no ground truth in
    a recording: no delay)."""
    from ..evaluation import teach as tt
    from ..methods import ready_method

    holds, rate = _read(profile, slides)
    x, y = profile.coordinates_mm
    counts = {}
    for label, settings in (("before", before), ("after", after)):
        method = ready_method(name, settings)
        counts[label] = [tt.slip_entries(tt.run(method, settings, x, y, rate, h)) for h in holds]
    return [f"slides: {h.name}: {b} slip(s) found before, {a} after"
            for h, b, a in zip(holds, counts["before"], counts["after"])]


def _minutes(hours: float) -> str:
    return f"{hours * 60:.1f} min"


_HEADER = re.compile(r"^\s*\[\s*([A-Za-z0-9_.\s\"-]+?)\s*\]\s*(#.*)?$")


def _header(line: str) -> str | None:
    m = _HEADER.match(line)
    if m is None or line.lstrip().startswith("[["):
        return None
    return ".".join(part.strip().strip('"') for part in m.group(1).split("."))


def set_keys(text: str, section: str, values: dict[str, float], where: str) -> str:
    """``text`` (a profile's TOML) with ``values`` set in ``[section]``: each key's line
    replaced where the section's own table has it, else added at the table's end; a
    table the file lacks is appended.  Everything else is kept as written.  A section
    written another way (dotted keys, an inline table) is refused: the edit would not
    be a conservative one."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if _header(line) == section), None)
    data = tomllib.loads(text)
    if start is None:
        node: Any = data
        for part in section.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        given = [k for k in values if isinstance(node, dict) and k in node]
        if given:
            raise OutputFileError(f"{where}: [{section}] {given[0]} is set outside a [{section}] table; "
                                  f"move it under one to let profile tune write it")
        tail = "" if not text or text.endswith("\n") else "\n"
        body = "".join(f"{k} = {_number(v)}\n" for k, v in values.items())
        return f"{text}{tail}\n# taught from the holds by `eskin-bus profile tune`\n[{section}]\n{body}"
    end = next((i for i in range(start + 1, len(lines)) if _header(lines[i]) is not None
                or lines[i].lstrip().startswith("[[")), len(lines))
    key_line = {k: re.compile(rf"^(\s*){re.escape(k)}\s*=") for k in values}
    missing = dict(values)
    for i in range(start + 1, end):
        for k, pattern in key_line.items():
            m = pattern.match(lines[i])
            if m is not None and k in missing:
                newline = "\n" if lines[i].endswith("\n") else ""
                lines[i] = f"{m.group(1)}{k} = {_number(missing.pop(k))}{newline}"
    last = end
    while last > start + 1 and not lines[last - 1].strip():
        last -= 1
    if last > 0 and not lines[last - 1].endswith("\n"):
        lines[last - 1] += "\n"
    lines[last:last] = [f"{k} = {_number(v)}\n" for k, v in missing.items()]
    out = "".join(lines)
    _check_edit(data, tomllib.loads(out), section, values, where)
    return out


def _check_edit(old: dict[str, Any], new: dict[str, Any], section: str, values: dict[str, float], where: str) -> None:
    """The edit changed exactly the keys asked for (a line the pattern misread would
    show here)."""
    def strip(d: dict[str, Any]) -> dict[str, Any]:
        out = dict(d)
        node = out
        parts = section.split(".")
        for part in parts[:-1]:
            node[part] = dict(node.get(part, {}))
            node = node[part]
        table = dict(node.get(parts[-1], {}))
        for k in values:
            table.pop(k, None)
        node[parts[-1]] = table
        return out

    node: Any = new
    for part in section.split("."):
        node = node.get(part, {})
    if strip(old) != strip(new) or any(not math.isclose(node.get(k, math.nan), v) for k, v in values.items()):
        raise OutputFileError(f"{where}: [{section}] could not be edited in place without touching other keys; "
                              f"set {', '.join(values)} by hand")


def _number(v: float) -> str:
    return repr(float(v))
