"""python -m ptwin.synth --out DIR --truth FILE [--effect TERM:PARAM=VALUE ...] [...]

Generates a recording set (shared/recording-format.md) with the named physics
concealed, and writes the truth (effects, parameters, K, E*, noise, seed) to a YAML
file *outside* the recording folder. Example, the bundled demo:

    python -m ptwin.synth --out data/demo --truth data/demo.truth.yaml \\
        --effect pore_pressure_relaxation:M=3.0e4

With ``--map NX NY`` it writes a force map instead (one recording set per spot, K and E*
varying smoothly over it, the ``--region-effect`` terms concealed inside a disc) and the
truth per spot as a CSV table:

    python -m ptwin.synth --map 16 16 --out map --truth map.truth.csv --speeds 2e-6 8e-6 40e-6 \\
        --samples 1000 --region-effect pore_pressure_relaxation:M=3.0e4
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

import yaml

from ptwin.checks import refuse_outside
from ptwin.data.recordings import MIN_SAMPLES, write_recordings
from ptwin.physics.terms import VOCABULARY
from ptwin.synth.maps import MapLayout, write_map
from ptwin.synth.simulator import EFFECTS, Experiment, Hold, simulate


class Refused(ValueError):
    """An option the synth cannot use, in one line: ``main`` prints it and exits with code 2, as every face does."""


def parse_holds(items: list[str], speeds: list[float] | None = None, creep: bool = False) -> tuple[Hold, ...]:
    """``DEPTH:SECONDS`` (a ramp-and-hold at every speed: each of ``speeds`` where given) or
    ``DEPTH:SECONDS:SPEED`` (at one), SI units; ``creep``: the force held instead of the base."""
    option, holds = "--creep" if creep else "--hold", []
    for item in items:
        try:
            values = [float(part) for part in item.split(":")]
        except ValueError:
            raise Refused(f"{option} {item!r}: write DEPTH:SECONDS or DEPTH:SECONDS:SPEED in SI units") from None
        if len(values) not in (2, 3) or values[0] <= 0 or values[1] < 0 or (len(values) == 3 and values[2] <= 0):
            raise Refused(f"{option} {item!r}: write DEPTH:SECONDS or DEPTH:SECONDS:SPEED, depth and speed > 0")
        if len(values) == 3 or speeds is None:
            holds.append(Hold(*values, creep=creep))
        else:
            holds += [Hold(*values, speed, creep) for speed in speeds]
    return tuple(holds)


def proposed_holds(diagnosis: Path | None) -> tuple[Hold, ...]:
    """The curves the confounded groups of ``diagnosis`` (a diagnosis.json) propose, each once."""
    if diagnosis is None:
        return ()
    try:
        groups = json.loads(diagnosis.read_text())["confounded"]
    except (OSError, ValueError, KeyError) as error:
        raise Refused(f"--next-experiment {diagnosis}: not a readable diagnosis.json ({error})") from None
    proposals = [group["next_experiment"] for group in groups if group.get("next_experiment")]
    if not proposals:
        raise Refused(f"--next-experiment {diagnosis}: it proposes no next experiment")
    distinct = {json.dumps([p["protocol"], p["repeats"]]): p for p in proposals}.values()  # groups may agree
    return tuple(hold for proposal in distinct for hold in Hold.proposed(proposal))


def parse_effects(items: list[str], option: str = "--effect") -> dict[str, dict[str, float]]:
    effects: dict[str, dict[str, float]] = {}
    for item in items:
        term, _, assignment = item.partition(":")
        name, _, value = assignment.partition("=")
        if term not in EFFECTS or not name or not value:
            raise Refused(f"{option} {item!r}: write TERM:PARAM=VALUE with TERM one of {', '.join(EFFECTS)}")
        try:
            effects.setdefault(term, {})[name] = float(value)
        except ValueError:
            raise Refused(f"{option} {item!r}: {value!r} is not a number") from None
    return effects


def physical_effects(effects: dict[str, dict[str, float]], probe_radius: float, option: str = "--effect") -> None:
    """``Refused`` (one line) where a vocabulary term's values are outside its physical range (the range a
    fit's ``Term.violation`` rejects, or a non-positive value of a parameter fitted in its log): the simulator would
    integrate them to NaN."""
    for term, values in effects.items():
        if term not in VOCABULARY:
            continue
        try:
            violation = VOCABULARY[term](probe_radius, **values).violation()
        except ValueError:  # math.log of a log-parameter ≤ 0
            violation = f"{', '.join(n for n, p in VOCABULARY[term].PARAMS.items() if p.log)} must be positive"
        if violation:
            raise Refused(f"{option} {term}: {values} is not physical ({violation})")


def refuse_out_of_range(args: argparse.Namespace) -> None:
    """``ValueError`` naming the first option out of its range (``ptwin.checks.refuse_outside``), as it is written."""
    positive = ("probe_radius", "spring_constant", "sample_thickness", "permeability", "effective_modulus", "spacing")
    at_least_zero = ("noise", "stiffness_spread", "contact_error", "baseline_offset", "seed")
    rules = [
        *((name, getattr(args, name) > 0, "positive") for name in positive),
        ("speeds", all(speed > 0 for speed in args.speeds), "positive [m/s]"),
        ("samples", args.samples >= MIN_SAMPLES, f"{MIN_SAMPLES} or more a curve (recording-format.md's least)"),
        ("sample_rate", args.sample_rate is None or args.sample_rate > 0, "positive [Hz]"),
        ("z_end", args.z_end > max(args.z_start, 0.0), "beyond contact (z = 0) and --z-start [m]"),
        *((name, getattr(args, name) >= 0, "0 or more") for name in at_least_zero),
        ("noise_correlation", -1.0 < args.noise_correlation < 1.0, "a lag-1 autocorrelation between -1 and 1"),
        ("noise_white_share", 0.0 <= args.noise_white_share <= 1.0, "a share from 0 to 1"),
        ("replicates", args.replicates >= 1, "1 or more"),
    ]
    refuse_outside(args, rules, lambda name: "--" + name.replace("_", "-"))


def _parser(defaults: Experiment) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m ptwin.synth", description=__doc__.split("\n\n")[1])
    parser.add_argument("--out", required=True, type=Path, help="recording-set folder to write")
    parser.add_argument("--truth", required=True, type=Path, help="truth YAML (with --map: CSV); keep it outside --out")
    parser.add_argument("--effect", action="append", default=[], help="TERM:PARAM=VALUE, repeatable")
    parser.add_argument(
        "--hold",
        action="append",
        default=[],
        help="DEPTH:SECONDS[:SPEED]: also record ramp-and-holds (approach to depth w, base fixed), repeatable",
    )
    parser.add_argument(
        "--creep",
        action="append",
        default=[],
        help="DEPTH:SECONDS[:SPEED]: also record creeps (approach to depth w, the force held there), repeatable",
    )
    parser.add_argument(
        "--next-experiment",
        type=Path,
        help="a diagnosis.json: also record the next experiment each of its confounded groups proposes",
    )
    parser.add_argument("--permeability", type=float, default=defaults.permeability, help="K [m²]")
    parser.add_argument("--effective-modulus", type=float, default=defaults.effective_modulus, help="E* [Pa]")
    parser.add_argument("--probe-radius", type=float, default=defaults.probe_radius, help="ρ [m]")
    parser.add_argument("--spring-constant", type=float, default=defaults.spring_constant, help="k_s [N/m]")
    parser.add_argument("--sample-thickness", type=float, default=defaults.sample_thickness, help="H0 [m]")
    parser.add_argument("--speeds", type=float, nargs="+", default=list(defaults.base_speeds), help="[m/s]")
    parser.add_argument(
        "--holds-only",
        action="store_true",
        help="record the holds and creeps alone (one without SPEED at each of --speeds), no approach-only curves",
    )
    parser.add_argument("--samples", type=int, default=defaults.samples, help="per curve")
    parser.add_argument("--z-start", type=float, default=defaults.z_start, help="first base displacement [m] (< 0)")
    parser.add_argument("--z-end", type=float, default=defaults.z_end, help="final base displacement [m]")
    parser.add_argument("--sample-rate", type=float, help="[Hz]: samples per curve from its duration (else --samples)")
    parser.add_argument("--noise", type=float, default=defaults.noise_std, help="force noise σ [N]")
    parser.add_argument(
        "--noise-correlation", type=float, default=0.0, help="lag-1 autocorrelation of the noise's AR(1) part"
    )
    parser.add_argument(
        "--noise-white-share", type=float, default=0.0, help="share of the noise variance that is white beside it"
    )
    parser.add_argument("--replicates", type=int, default=1, help="curves per speed (v5, v5b, ...)")
    parser.add_argument("--stiffness-spread", type=float, default=0.0, help="relative std of E* between curves")
    parser.add_argument(
        "--contact-error",
        type=float,
        default=0.0,
        help="std of each curve's contact error [m]; writes contact_point: estimate",
    )
    parser.add_argument("--baseline-offset", type=float, default=0.0, help="std of each curve's force offset [N]")
    parser.add_argument("--tilt", type=float, default=0.0, help="baseline slope dF/dz [N/m]")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--map", type=int, nargs=2, metavar=("NX", "NY"), help="write a force map of NX × NY spots")
    parser.add_argument("--spacing", type=float, default=5e-6, help="--map: distance between spots [m]")
    parser.add_argument("--variation", type=float, default=0.4, help="--map: relative change of K and E* over it")
    parser.add_argument(
        "--region-effect", action="append", default=[], help="--map: TERM:PARAM=VALUE inside the disc, repeatable"
    )
    parser.add_argument("--region-radius", type=float, help="--map: the disc's radius [m] (default 0.3 × the map)")
    return parser


def main(argv: list[str] | None = None) -> None:
    args = _parser(Experiment()).parse_args(argv)
    try:
        _generate(args)
    except Refused as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None


def _generate(args: argparse.Namespace) -> None:
    """The recording set (or map) and its truth that ``args`` ask for, or ``Refused`` saying what cannot be."""
    if args.truth.resolve().is_relative_to(args.out.resolve()):
        raise Refused(f"--truth {args.truth}: keep the truth outside the recording folder {args.out}")
    try:
        refuse_out_of_range(args)  # first: a term's physical range is read against --probe-radius
    except ValueError as error:
        raise Refused(str(error)) from None
    effects, region = parse_effects(args.effect), parse_effects(args.region_effect, "--region-effect")
    physical_effects(effects, args.probe_radius)
    physical_effects(region, args.probe_radius, "--region-effect")
    try:
        experiment = Experiment(
            probe_radius=args.probe_radius,
            spring_constant=args.spring_constant,
            sample_thickness=args.sample_thickness,
            permeability=args.permeability,
            effective_modulus=args.effective_modulus,
            base_speeds=() if args.holds_only else tuple(args.speeds),
            samples=args.samples,
            z_start=args.z_start,
            z_end=args.z_end,
            sample_rate=args.sample_rate,
            noise_std=args.noise,
            noise_correlation=args.noise_correlation,
            noise_white_share=args.noise_white_share,
            replicates=args.replicates,
            stiffness_spread=args.stiffness_spread,
            contact_point="estimate" if args.contact_error or args.baseline_offset or args.tilt else "known",
            contact_error=args.contact_error,
            baseline_offset=args.baseline_offset,
            tilt=args.tilt,
            holds=parse_holds(args.hold, args.speeds if args.holds_only else None)
            + parse_holds(args.creep, args.speeds if args.holds_only else None, creep=True)
            + proposed_holds(args.next_experiment),
            seed=args.seed,
            effects=effects,
        )
    except ValueError as error:
        raise Refused(str(error)) from None
    if args.map:
        try:
            layout = MapLayout(
                *args.map,
                args.spacing,
                args.variation,
                region,
                region_radius=args.region_radius,
            )
        except ValueError as error:
            raise Refused(str(error)) from None
        table = write_map(args.out, args.truth, experiment, layout)
        print(f"wrote {args.out} ({len(table)} spots, {int(table['in_region'].sum())} in the region) and {args.truth}")
        return
    meta, curves = simulate(experiment)
    write_recordings(args.out, meta, curves)
    truth = {"format": "ptwin-truth/1", "recordings": str(args.out), **asdict(experiment)}
    truth["base_speeds"] = list(experiment.base_speeds)
    truth["holds"] = [asdict(hold) for hold in experiment.holds]
    args.truth.parent.mkdir(parents=True, exist_ok=True)
    args.truth.write_text(yaml.safe_dump(truth, sort_keys=False))
    print(
        f"wrote {args.out} ({len(curves)} samples, curves {', '.join(dict.fromkeys(curves['curve']))}) and {args.truth}"
    )
