"""The ``grindtwin`` command.

Exit codes: 0 success, 2 bad input (one clear line, no traceback), 1 a run that failed.
"""

from __future__ import annotations

import argparse
import json
import sys

from twin.errors import SolverError, TwinError, TwinInputError

from .errors import RunError, SceneError


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad argument in one line and exits 2."""

    def error(self, message):
        sys.stderr.write(f"grindtwin: error: {message}\n")
        raise SystemExit(2)


def _float_in(name, lo, hi, lo_open=False, hi_open=False):
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number. Got {text!r}.") from None
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            br = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
            raise argparse.ArgumentTypeError(f"{name} must be in {br}. Got {text}.")
        return v
    return parse


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="grindtwin", description="Digital twin of ore grinding and its model predictive controller.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("steady", help="steady-state KPIs of the mill for an ore or a blend")
    s.add_argument("--ore", default="B", help="reference type A-D or a TOML file with [mineralogy] and [texture]")
    s.add_argument("--blend", help="blend of ores, e.g. B=0.6,D=0.4 (overrides --ore)")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--feed-tph", type=_float_in("--feed-tph", 0, 1e5), help="fresh feed rate [t/h]")
    g.add_argument("--at-constant-load", action="store_true",
                   help="solve for the feed rate that holds the nominal hold-up")
    s.add_argument("--speed", type=_float_in("--speed", 0, 1, True, True), default=None,
                   help="mill speed as a fraction of critical (0.70, not 70)")
    s.add_argument("--mill", default="lab", choices=["lab", "industrial"])
    s.add_argument("--json", action="store_true", help="print the KPIs as JSON (unit-suffixed keys)")

    c = sub.add_parser("calibrate", help="regenerate twin/data/calibration.json from the repository")
    c.add_argument("--fast", action="store_true", help="a quick, coarser calibration (a check)")
    c.add_argument("--out", help="write here instead of the shipped file")
    return p


def cmd_steady(args) -> int:
    from twin.ores import Blend, load_ore
    from twin.twin import Twin

    blend = Blend.parse(args.blend) if args.blend else Blend.single(load_ore(args.ore))
    twin = Twin(blend, mill=args.mill)
    if args.at_constant_load:
        ss = twin.steady_at_constant_load(speed_frac_critical=args.speed)
    else:
        ss = twin.steady(feed_tph=args.feed_tph, speed_frac_critical=args.speed)
    kpis = {k: v for k, v in ss.summary().items()
            if k in ("feed_tph", "speed_frac_critical", "p80_um", "specific_energy_kwh_t", "power_kw",
                     "throughput_tph", "holdup_t", "load_frac", "load_status")}
    mineralogy = {o.name: {"wt_pct": o.wt_pct, **o.summary()} for o in blend.ores}
    if args.json:
        print(json.dumps({"mill": args.mill, "blend": dict(zip(blend.names, blend.fractions)),
                          **kpis, "mineralogy": mineralogy}, indent=2))
        return 0
    print(f"Mill {args.mill}, blend " + ", ".join(f"{n} {f:.0%}" for n, f in zip(blend.names, blend.fractions)))
    for key, val in kpis.items():
        print(f"  {key:24s} {val:.4g}" if isinstance(val, float) else f"  {key:24s} {val}")
    for ore in blend.ores:
        wt = ", ".join(f"{m} {w:.1f}" for m, w in sorted(ore.wt_pct.items(), key=lambda kv: -kv[1]))
        print(f"  ore {ore.name}: H_min {ore.hardness_index_gpa:.2f} GPa, textural index "
              f"{ore.textural_index:.2f}; wt%: {wt}")
    return 0


def cmd_calibrate(args) -> int:
    from twin import calibration

    argv = (["--fast"] if args.fast else []) + (["--out", args.out] if args.out else [])
    return calibration.main(argv)


COMMANDS = {"steady": cmd_steady, "calibrate": cmd_calibrate}


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except (TwinInputError, SceneError) as exc:
        sys.stderr.write(f"grindtwin: error: {exc}\n")
        return 2
    except (SolverError, RunError, TwinError) as exc:
        sys.stderr.write(f"grindtwin: {args.command} failed: {exc}\n")
        return 1


if __name__ == "__main__":
    sys.exit(main())
