"""``eskin-bus evaluate --closed-loop``: every method in the virtual cell, scored by
what a cell owner pays for (sim/cell, docs/evaluation.md *The closed loop*)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import click

from ..methods import detector_names
from .console import Ticker, echo_json

#: The baselines beside the methods: the cautious fixed grip (no skin, no program), the
#: light grip with no slip sensing, and the program fed the truth.
BASELINES = ("fixed", "none", "oracle")


def cell_seeds(value: str, parse: Any) -> tuple[str, tuple[int, ...]]:
    """``evaluation`` / ``fresh`` / ``tuning`` are the closed loop's own seed sets;
    otherwise ``parse``."""
    from ..sim.cell.episodes import EVALUATION_SEEDS, FRESH_SEEDS, TUNING_SEEDS

    if value == "evaluation":
        return "closed-loop evaluation", EVALUATION_SEEDS
    if value == "fresh":
        return "closed-loop fresh", FRESH_SEEDS
    if value == "tuning":
        return "closed-loop tuning", TUNING_SEEDS
    return value, parse(value)


def setup_of(rate_hz: float, plc_cycle_ms: float, conditions: tuple[str, ...]) -> Any:
    from ..sim.cell.runner import Setup
    from ..sim.cell.sweeps import CONDITIONS, NAMED, ZERO_ALLOWED, apply

    setup = apply(apply(Setup(), "rate", rate_hz), "plc_cycle", plc_cycle_ms)
    for item in conditions:
        name, _, value = item.partition("=")
        if name in NAMED:
            names = NAMED[name][1]
            if value not in names:
                raise click.BadParameter(f"{item!r}: expected {name}= one of {', '.join(names)}", param_hint="--cell")
            setup = apply(setup, name, value)
            continue
        if name not in CONDITIONS:
            raise click.BadParameter(f"{item!r}: expected NAME=VALUE with NAME one of "
                                     f"{', '.join([*CONDITIONS, *NAMED])}", param_hint="--cell")
        try:
            number = float(value)
        except ValueError:
            raise click.BadParameter(f"{item!r}: expected a number after '='", param_hint="--cell") from None
        if not (math.isfinite(number) and number >= 0) or (number == 0 and name not in ZERO_ALLOWED):
            raise click.BadParameter(f"{item!r}: expected a positive number", param_hint="--cell")
        if name == "force_drop" and number >= 1:
            raise click.BadParameter(f"{item!r}: expected a share below 1", param_hint="--cell")
        setup = apply(setup, name, number)
    return setup


def controls_of(methods: tuple[str, ...]) -> tuple[str, ...]:
    """The controls to run: the methods asked for (baselines by name too), or every
    detector between the baselines."""
    if methods:
        return tuple(dict.fromkeys(methods))
    return ("fixed", "none", *detector_names(), "oracle")


def closed_loop(methods: tuple[str, ...], seeds_opt: str, parse_seeds: Any, rate_hz: float, plc_cycle_ms: float,
                conditions: tuple[str, ...], sweep: str | None, jobs: int, charts_dir: str | None, fmt: str,
                tune: bool = False) -> None:
    from ..sim.cell.runner import run_controls

    default = _default_method()
    if tune:
        _tune(methods[0] if methods else default, jobs)
        return
    label, seeds = cell_seeds(seeds_opt, parse_seeds)
    setup = setup_of(rate_hz, plc_cycle_ms, conditions)
    header = (f"# eskin-bus evaluate --closed-loop --seeds {seeds_opt} --rate {rate_hz:g} --plc-cycle {plc_cycle_ms:g}"
              + "".join(f" --cell {c}" for c in conditions))
    if charts_dir is not None:
        _charts(Path(charts_dir), methods, label, seeds, setup, jobs, default, header + f" --charts {charts_dir}")
        return
    if sweep is not None:
        _sweep(sweep, methods or ("fixed", "none", default, "oracle"), label, seeds, setup, jobs, fmt)
        return
    controls = controls_of(methods)
    if "oracle" not in controls:
        controls = (*controls, "oracle")  # every figure against the oracle needs it
    start = time.perf_counter()
    with Ticker(len(seeds) * len(controls), "closed loop") as ticker:
        res = run_controls(controls, seeds, setup, jobs, ticker)
    scores = _scores(res)
    seconds = time.perf_counter() - start
    if fmt == "json":
        echo_json({"seeds": label, "seed_list": list(seeds), "setup": _setup_dict(setup), "seconds": seconds,
                   "default_method": default, "methods": [s.as_dict() for s in scores.values()]})
        return
    click.echo(header + f"  ({len(seeds)} episodes, {_hours(scores):.2f} h of holding per control, {seconds:.0f} s)")
    _table(scores.values())
    _per_object(scores.values())
    _targets(scores, default)


def _default_method() -> str:
    from ..profile import load_profile

    return load_profile("paper-5x5").detector.method


def _scores(res: dict[str, list[Any]]) -> dict[str, Any]:
    from ..sim.cell.scoring import score

    oracle = res.get("oracle")
    return {c: score(c, rs, oracle) for c, rs in res.items()}


def _hours(scores: dict[str, Any]) -> float:
    return max((s.holding_h for s in scores.values()), default=0.0)


def _setup_dict(setup: Any) -> dict[str, Any]:
    from ..sim.cell.physics import VISCOUS_S_PER_M

    c, b = setup.chain, setup.batch
    return {"rate_hz": c.rate_hz, "plc_cycle_ms": c.plc_cycle_s * 1000, "actuator_rate_n_per_s": c.actuator.rate_n_per_s,
            "dead_time_ms": c.actuator.dead_s * 1000, "extra_latency_ms": c.extra_latency_s * 1000,
            "viscous_s_per_m": c.viscous_s_per_m if c.viscous_s_per_m is not None else VISCOUS_S_PER_M,
            "stribeck_mm_s": b.stribeck_mm_s, "force_drop": b.force_drop, "gripper_min_n": c.actuator.min_n,
            "gripper_max_n": c.actuator.max_n, "gripper_step_n": c.actuator.step_n,
            "gripper_error_share": c.actuator.error_share,
            "mass_scale": b.mass_scale, "friction_scale": b.mu_scale, "accel_scale": b.accel_scale, "scan_to_plc_median_ms": c.scan_to_plc.median_s * 1000,
            "plc_to_gripper_median_ms": c.plc_to_gripper.median_s * 1000}


def _num(v: float, fmt: str = ".1f") -> str:
    return format(v, fmt) if math.isfinite(v) else "-"


def _table(scores: Any) -> None:
    click.echo("| control | held (%) | of the oracle's | dropped | crushed (fragile) | slid p50 / p90 (mm) | "
               "needless squeezes (per h) | raises | mean grip / fixed | slide -> raise p50 / p90 (ms) |")
    click.echo("|---|---|---|---|---|---|---|---|---|---|")
    for s in scores:
        click.echo(f"| {s.control} | {100 * s.held_share:.1f} | {_num(100 * s.of_oracle)} % | {s.dropped} | "
                   f"{s.crushed} ({s.fragile}) | {_num(s.slid_p50_mm)} / {_num(s.slid_p90_mm)} | "
                   f"{s.needless} ({_num(s.needless_per_hour)}) | {s.raises} | {_num(100 * s.grip_vs_fixed, '.0f')} % | "
                   f"{_num(s.reaction_p50_s * 1000, '.0f')} / {_num(s.reaction_p90_s * 1000, '.0f')} |")


def _per_object(scores: Any) -> None:
    click.echo("")
    rows = list(scores)
    names = [o[0] for o in rows[0].per_object] if rows else []
    click.echo("| control | " + " | ".join(f"{n}: held / dropped / crushed" for n in names) + " |")
    click.echo("|---|" + "---|" * len(names))
    for s in rows:
        cells = {o[0]: o for o in s.per_object}
        click.echo(f"| {s.control} | " + " | ".join(
            f"{cells[n][2]} / {cells[n][3]} / {cells[n][4]} of {cells[n][1]}" if n in cells else "-" for n in names) + " |")


def _targets(scores: dict[str, Any], default: str) -> None:
    """The issue's targets for the default method, met or not, from this run."""
    d, fixed = scores.get(default), scores.get("fixed")
    if d is None or fixed is None:
        return
    click.echo("")
    checks = [
        (f"{default} holds >= 98 % of what the oracle holds", d.of_oracle >= 0.98, f"{_num(100 * d.of_oracle)} %"),
        (f"{default}: <= 1 needless squeeze per hour of holding", d.needless_per_hour <= 1.0,
         f"{d.needless} in {d.holding_h:.2f} h ({_num(d.needless_per_hour, '.2f')} per h)"),
        (f"{default}: no fragile object crushed that the oracle holds", d.crushed_of_oracle == 0,
         f"{d.crushed_of_oracle} crushed"),
        (f"{default}: mean grip <= 60 % of the fixed grip's", d.grip_vs_fixed <= 0.60, f"{_num(100 * d.grip_vs_fixed)} %"),
        (f"{default}: drops no more than the fixed grip", d.dropped <= fixed.dropped,
         f"{d.dropped} against {fixed.dropped}"),
    ]
    for what, ok, figure in checks:
        click.echo(f"# target: {what}: {figure}: {'met' if ok else 'NOT MET'}")


def _sweep(name: str, controls: tuple[str, ...], label: str, seeds: tuple[int, ...], setup: Any, jobs: int,
           fmt: str) -> list[tuple[float | str, dict[str, Any]]]:
    from ..sim.cell.runner import run_controls
    from ..sim.cell.sweeps import CONDITIONS, NAMED, NAMED_SWEEPS, SWEEPS, apply

    values: tuple[float | str, ...]
    condition, values = SWEEPS[name] if name in SWEEPS else NAMED_SWEEPS[name]
    desc, unit = (CONDITIONS[condition][0], CONDITIONS[condition][1]) if condition in CONDITIONS else \
        (NAMED[condition][0], "class")
    if "oracle" not in controls:
        controls = (*controls, "oracle")
    out = []
    start = time.perf_counter()
    with Ticker(len(seeds) * len(controls) * len(values), f"sweep {name}") as ticker:
        for value in values:
            res = run_controls(controls, seeds, apply(setup, condition, value), jobs, ticker)
            out.append((value, _scores(res)))
    if fmt == "json":
        echo_json({"sweep": name, "condition": condition, "unit": unit, "seeds": label, "seed_list": list(seeds),
                   "setup": _setup_dict(setup), "seconds": time.perf_counter() - start,
                   "points": [{"value": v, "methods": [s.as_dict() for s in sc.values()]} for v, sc in out]})
        return out
    click.echo(f"# eskin-bus evaluate --closed-loop --sweep {name} --seeds {label}: {desc} ({unit}); "
               f"{len(seeds)} episodes a point, {time.perf_counter() - start:.0f} s")
    click.echo(f"| {condition} ({unit}) | control | held (%) | of the oracle's | dropped | crushed | slid p90 (mm) | "
               "needless squeezes (per h) | mean grip / fixed | slide -> raise p50 (ms) |")
    click.echo("|---|---|---|---|---|---|---|---|---|---|")
    for value, scores in out:
        for s in scores.values():
            click.echo(f"| {_value(value)} | {s.control} | {100 * s.held_share:.1f} | {_num(100 * s.of_oracle)} % | "
                       f"{s.dropped} | {s.crushed} | {_num(s.slid_p90_mm)} | {s.needless} ({_num(s.needless_per_hour)}) | "
                       f"{_num(100 * s.grip_vs_fixed, '.0f')} % | {_num(s.reaction_p50_s * 1000, '.0f')} |")
    return out


def _value(value: float | str) -> str:
    return value if isinstance(value, str) else format(value, "g")


def _charts(out: Path, methods: tuple[str, ...], label: str, seeds: tuple[int, ...], setup: Any, jobs: int,
            default: str, header: str) -> None:
    """The table of the main run (as without --charts), then the latency sweep, and the
    two charts drawn from them."""
    from ..sim.cell.charts import held_vs_latency, held_vs_squeezes
    from ..sim.cell.runner import run_controls
    from ..sim.cell.sweeps import SWEEPS, apply

    out.mkdir(parents=True, exist_ok=True)
    controls = controls_of(methods)
    if "oracle" not in controls:
        controls = (*controls, "oracle")
    start = time.perf_counter()
    with Ticker(len(seeds) * len(controls), "closed loop") as ticker:
        scores = _scores(run_controls(controls, seeds, setup, jobs, ticker))
    click.echo(f"{header}  ({len(seeds)} episodes, {_hours(scores):.2f} h of holding per control, "
               f"{time.perf_counter() - start:.0f} s)")
    _table(scores.values())
    _per_object(scores.values())
    _targets(scores, default)
    title = f"the closed loop, {label} seeds ({len(seeds)} episodes), {setup.chain.rate_hz:g} Hz, " \
            f"{setup.chain.plc_cycle_s * 1000:g} ms PLC cycle"
    held_vs_squeezes(list(scores.values()), out / "closed-loop-held-vs-squeezes.png", title)
    click.echo(f"wrote {out / 'closed-loop-held-vs-squeezes.png'}")
    _, values = SWEEPS["latency"]
    reacting = tuple(c for c in (default, "oracle") if c in controls)
    points: dict[str, list[tuple[float, float]]] = {c: [] for c in reacting}
    dead_ms = setup.chain.actuator.dead_s * 1000
    with Ticker(len(seeds) * len(reacting) * len(values), "latency sweep") as ticker:
        for value in values:
            sc = scores if value == 0 else _scores(run_controls(reacting, seeds, apply(setup, "latency", value), jobs,
                                                                ticker))
            for c in reacting:
                s = sc[c]
                points[c].append((s.reaction_p50_s * 1000 + dead_ms, 100 * s.held_share))
                click.echo(f"# latency +{value:g} ms: {c} held {100 * s.held_share:.1f} % ({s.dropped} dropped, "
                           f"{s.crushed} crushed), slide -> raise p50 {s.reaction_p50_s * 1000:.0f} ms "
                           f"(+ {dead_ms:g} ms dead time), slid p90 {s.slid_p90_mm:.1f} mm")
    floors: dict[str, float] = {c: 100 * scores[c].held_share for c in ("fixed", "none") if c in scores}
    held_vs_latency(points, out / "closed-loop-held-vs-latency.png", title, floors)
    click.echo(f"wrote {out / 'closed-loop-held-vs-latency.png'}")


def _tune(method: str, jobs: int) -> None:
    """The recipes' choices, remade on the tuning seeds (sim/cell/tuning.py)."""
    from ..sim.cell.tuning import (
        GRIP_LIMIT,
        SAFETY_CANDIDATES,
        TUNING_SEEDS,
        chosen,
        chosen_safety,
        fixed_safety,
        policy_candidates,
    )
    from ..sim.cell.tuning import POLICY_CANDIDATES as CANDIDATES

    n = len(TUNING_SEEDS)
    click.echo(f"# eskin-bus evaluate --closed-loop --tune  ({n} tuning episodes, seeds {TUNING_SEEDS[0]}.."
               f"{TUNING_SEEDS[-1]}; the default 100 Hz, 10 ms PLC cycle)")
    with Ticker(n * (len(SAFETY_CANDIDATES) + 2 * len(CANDIDATES)), "tuning") as ticker:
        rows = fixed_safety(jobs=jobs, progress=ticker)
        click.echo("| fixed grip: safety factor | held | dropped | crushed |")
        click.echo("|---|---|---|---|")
        for safety, s in rows:
            click.echo(f"| {safety:g} | {s.held} | {s.dropped} | {s.crushed} |")
        click.echo(f"# chosen: the smallest with nothing dropped: {chosen_safety(rows)}")
        cands = policy_candidates(method, jobs=jobs, progress=ticker)
    click.echo(f"| light | step | mode | escalate (mm) | repeat (s) | relax share / floor / time (s) | {method}: held | dropped "
               "| crushed | needless (per h) | grip / fixed | oracle: held | dropped | needless | grip / fixed |")
    click.echo("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cands:
        f, m, o = c.factors, c.method, c.oracle
        escalate = f"{f.escalate_mm:g}" if f.mode == "hybrid" else "-"
        click.echo(f"| {f.light:g} | {f.step:g} | {f.mode} | {escalate} | {f.repeat_s:g} | {f.relax_share:g} / "
                   f"{f.relax_floor:g} / {f.relax_s:g} | {m.held} | {m.dropped} | {m.crushed} | {m.needless} ({_num(m.needless_per_hour)}) "
                   f"| {_num(100 * m.grip_vs_fixed, '.0f')} % | {o.held} | {o.dropped} | {o.needless} | "
                   f"{_num(100 * o.grip_vs_fixed, '.0f')} % |")
    best = chosen(cands)
    click.echo(f"# chosen (the most held, then the fewest needless squeezes, then the lightest grip, gripping at "
               f"most {100 * GRIP_LIMIT:.0f} % of the fixed grip): {best.factors if best else 'none'}")



def check_options(closed: bool, **given: Any) -> None:
    """Options that belong to one side only."""
    if closed:
        option = {"per_family": "per-family", "hold_out": "hold-out-family", "long_holds": "long-holds",
                  "per_scene": "per-scene", "scenes": "scene", "conditions": "condition", "within_ms": "within",
                  "only_charts": "only"}
        bad = [k for k, v in given.items() if v and k in option]
        if bad:
            raise click.UsageError(f"--closed-loop runs the virtual cell: leave out --{option[bad[0]]}")
    else:
        bad = [k for k, v in given.items() if v and k in ("cell", "sweep", "jobs_set", "plc_cycle_set", "tune")]
        if bad:
            name = {"jobs_set": "jobs", "plc_cycle_set": "plc-cycle"}.get(bad[0], bad[0])
            raise click.UsageError(f"--{name} belongs to the closed loop: give --closed-loop too")

