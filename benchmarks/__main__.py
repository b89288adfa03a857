"""The nightly benchmark evaluation: ``python -m benchmarks [--quick] [--only NAME ...]``.

Runs every ``benchmarks/bench_*.py`` suite (quality and speed), writes
``benchmarks/results/<date>-<commit>.json``, appends a line to
``benchmarks/results/history.jsonl``, and prints a comparison with the previous
result of the same mode that flags quality drops and slowdowns beyond noise.

What is compared: each suite's ``tracked`` dict, ``{metric: {"value": v,
"better": "higher"|"lower", "kind": "quality"|"speed"}}``.  Speed metrics are
ratios to a reference measured in the same run wherever a suite has one, so a
busier machine moves both sides.  The noise band of a metric is three standard
deviations of its last values in the history (at least 2 earlier results),
and never less than a floor: 0.01 absolute for quality, 10 % relative for speed.
"""
from __future__ import annotations

import argparse
import datetime as dt
import importlib
import json
import math
import pathlib
import pkgutil
import statistics
import subprocess
import sys
import time
import traceback
from typing import Any

import benchmarks
from benchmarks.common import format_table, report

RESULTS = pathlib.Path(__file__).resolve().parent / "results"
HISTORY = RESULTS / "history.jsonl"
QUALITY_FLOOR = 0.01
SPEED_FLOOR = 0.10
NOISE_WINDOW = 5


def suites() -> list[str]:
    """Names of the benchmark modules, in a stable order."""
    return sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True, cwd=RESULTS.parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_suites(names: list[str], quick: bool) -> dict[str, Any]:
    """Run each suite; a failing suite is recorded as failed and the others still run."""
    out: dict[str, Any] = {}
    for name in names:
        print(f"\n### {name}{' (quick)' if quick else ''}", flush=True)
        t0 = time.perf_counter()
        try:
            mod = importlib.import_module(f"benchmarks.{name}")
            result = mod.run(quick=quick)
            report(result)
            result["seconds"] = round(time.perf_counter() - t0, 1)
            out[name] = result
        except Exception as exc:  # noqa: BLE001 - a broken suite is a finding, not a crash
            traceback.print_exc()
            out[name] = {"name": name, "error": f"{type(exc).__name__}: {exc}",
                         "seconds": round(time.perf_counter() - t0, 1)}
    return out


def load_history(quick: bool) -> list[dict[str, Any]]:
    if not HISTORY.exists():
        return []
    rows = []
    for line in HISTORY.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if rec.get("quick") == quick:
            rows.append(rec)
    return rows


def flatten(suites_result: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``suite.metric`` -> its tracked entry."""
    flat = {}
    for suite, res in suites_result.items():
        for metric, entry in (res.get("tracked") or {}).items():
            if isinstance(entry, dict) and isinstance(entry.get("value"), (int, float)):
                flat[f"{suite}.{metric}"] = entry
    return flat


def compare(current: dict[str, dict[str, Any]], history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows comparing each tracked metric with the previous result and the noise of the history."""
    past = [h.get("tracked", {}) for h in history]
    rows = []
    for key, entry in sorted(current.items()):
        values = [p[key]["value"] for p in past if key in p and isinstance(p[key].get("value"), (int, float))]
        value, better, kind = float(entry["value"]), entry.get("better", "higher"), entry.get("kind", "quality")
        row = {"metric": key, "kind": kind, "value": value, "previous": values[-1] if values else "", "flag": ""}
        if values:
            prev = float(values[-1])
            recent = values[-NOISE_WINDOW:]
            sd = statistics.pstdev(recent) if len(recent) >= 2 else 0.0
            floor = QUALITY_FLOOR if kind == "quality" else SPEED_FLOOR * abs(prev)
            band = max(3 * sd, floor)
            worse = (prev - value) if better == "higher" else (value - prev)
            row["noise"] = round(band, 4)
            if math.isfinite(worse) and worse > band:
                row["flag"] = "QUALITY DROP" if kind == "quality" else "SLOWDOWN"
            elif math.isfinite(worse) and -worse > band:
                row["flag"] = "better"
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="tiny inputs: checks the suites still run (CI)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these suites (e.g. bench_spaces)")
    parser.add_argument("--no-save", action="store_true", help="do not write results or history")
    parser.add_argument("--list", action="store_true", help="list the suites and exit")
    args = parser.parse_args(argv)
    names = suites()
    if args.list:
        print("\n".join(names))
        return 0
    if args.only:
        unknown = [n for n in args.only if n not in names]
        if unknown:
            print(f"benchmarks: error: unknown suite(s) {unknown}; known: {names}", file=sys.stderr)
            return 2
        names = args.only
    started = dt.datetime.now(dt.UTC)
    results = run_suites(names, args.quick)
    tracked = flatten(results)
    history = load_history(args.quick)
    rows = compare(tracked, history)
    record = {"date": started.isoformat(timespec="seconds"), "commit": commit(), "quick": args.quick,
              "suites": results, "tracked": tracked,
              "seconds": round((dt.datetime.now(dt.UTC) - started).total_seconds(), 1)}
    if not args.no_save:
        RESULTS.mkdir(exist_ok=True)
        path = RESULTS / f"{started:%Y-%m-%d}-{record['commit']}{'-quick' if args.quick else ''}.json"
        path.write_text(json.dumps(record, indent=1, default=float))
        with HISTORY.open("a") as f:
            f.write(json.dumps({k: record[k] for k in ("date", "commit", "quick", "tracked", "seconds")},
                               default=float) + "\n")
        print(f"\nresults: {path}")
    print("\n== comparison with the previous result ==")
    print(format_table(rows, ["metric", "kind", "value", "previous", "noise", "flag"]) if rows
          else "(no tracked metrics)")
    failed = [n for n, r in results.items() if "error" in r]
    flags = [r for r in rows if r["flag"] in ("QUALITY DROP", "SLOWDOWN")]
    print(f"\n{len(names)} suites in {record['seconds']} s; {len(failed)} failed; {len(flags)} flagged")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
