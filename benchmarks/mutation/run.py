"""Mutation testing of the core modules (issue 21): how many planted one-line bugs the tests catch.

For each core module listed in ``modules.toml`` (next to this file) this runs mutmut over the
module's source files with only the module's own tests, then writes the score, every surviving
mutant with its diff, and the mutants listed as equivalent (with the reason) to
``benchmarks/results/mutation.json`` and a readable table ``benchmarks/results/mutation.md``.

Score = killed / (mutants − equivalent); a mutant no selected test runs counts as surviving,
a timeout as killed (the mutant changed behaviour). The first recorded run of a module stays as
its ``before`` figure; every later run replaces ``after`` (``--reset-baseline`` starts over).

Each module runs in its own scratch folder ``build/mutation/<module>/`` holding links to the
packages and the tests, a copy of ``pyproject.toml`` with the module's ``[tool.mutmut]`` section,
and a link ``shared`` so the tests find ``../shared/data`` from mutmut's ``mutants/`` copy.

Run: ``make mutation`` (every module, hours on 2 cores) or ``make mutation MODULE=calibration.distortion``
(one module, minutes); ``--list`` prints the modules. Not part of ``make test``.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
RESULTS = REPO / "benchmarks" / "results"
SCRATCH = REPO / "build" / "mutation"
PACKAGES = ("rigs", "calibration", "studio")

sys.path.insert(0, str(REPO))
from rigs.atomic import atomic_write_json, atomic_write_text  # noqa: E402

KILLED = {"killed", "timeout", "segfault", "caught by type check"}
SURVIVED = {"survived", "no tests", "suspicious"}


def load_plan(path: Path = HERE / "modules.toml") -> tuple[dict[str, dict], list[dict]]:
    """Modules (name → files, tests, optional pytest ``-k`` ``select`` and mutant-name patterns
    ``mutants``) and the equivalent-mutant list (``equivalent/<module>.toml``, one file a module)."""
    data = tomllib.loads(path.read_text("utf-8"))
    modules = data.get("modules", {})
    for name, spec in modules.items():
        for field in ("files", "tests"):
            if not spec.get(field):
                raise ValueError(f"{path}: modules.{name}.{field}: expected a non-empty list of paths")
            for entry in spec[field]:
                if not list(REPO.glob(entry)):
                    raise ValueError(f"{path}: modules.{name}.{field}: {entry!r} matches no file")
    equivalents = []
    for listing in sorted((path.parent / "equivalent").glob("*.toml")):
        if listing.stem not in modules:
            raise ValueError(f"{listing}: expected the name of a module of {path.name}")
        for i, entry in enumerate(tomllib.loads(listing.read_text("utf-8")).get("equivalent", [])):
            for field in ("mutant", "line", "reason"):
                if not entry.get(field):
                    raise ValueError(f"{listing}: equivalent[{i}].{field}: expected a non-empty string")
            equivalents.append(entry)
    return modules, equivalents


def prepare_scratch(name: str, spec: dict) -> Path:
    """A fresh folder where mutmut sees the repo with this module's configuration."""
    folder = SCRATCH / name
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for entry in (*PACKAGES, "tests"):
        (folder / entry).symlink_to(REPO / entry, target_is_directory=True)
    (folder / "shared").symlink_to(REPO.parent / "shared", target_is_directory=True)
    config = {
        "source_paths": list(PACKAGES),
        "only_mutate": list(spec["files"]),
        "pytest_add_cli_args_test_selection": list(spec["tests"]) + (["-k", spec["select"]] if spec.get("select") else []),
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-x", "-q", "--no-header"],
        "timeout_multiplier": 10.0,
        "use_git_change_detection": False,
    }
    lines = [(REPO / "pyproject.toml").read_text("utf-8"), "", "[tool.mutmut]"]
    lines += [f"{key} = {json.dumps(value)}" for key, value in config.items()]
    (folder / "pyproject.toml").write_text("\n".join(lines) + "\n", "utf-8")
    return folder


def mutmut_version() -> str:
    from importlib.metadata import version

    return version("mutmut")


def run_mutmut(folder: Path, patterns: list[str]) -> float:
    """Run mutmut in ``folder`` (one worker); return the wall time in seconds."""
    log = folder / "mutmut.log"
    t0 = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.run(
            [sys.executable, "-m", "mutmut", "run", "--max-children", "1", *patterns],
            cwd=folder, stdout=out, stderr=subprocess.STDOUT,
        )
    if proc.returncode != 0:
        tail = log.read_text("utf-8", errors="replace")[-3000:]
        raise RuntimeError(f"mutmut failed in {folder} (exit {proc.returncode}); end of {log}:\n{tail}")
    return time.perf_counter() - t0


def collect(folder: Path, spec: dict, patterns: list[str]) -> dict[str, tuple[str, str]]:
    """Mutant name → (status, diff) for the module's files, read from mutmut's meta files."""
    from mutmut.stats import status_by_exit_code

    found: dict[str, tuple[str, str]] = {}
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        from mutmut.mutation.diff_apply import get_diff_for_mutant

        for entry in spec["files"]:
            for source in sorted(REPO.glob(entry)):
                rel = source.relative_to(REPO)
                meta = Path("mutants") / f"{rel}.meta"
                if not meta.exists():
                    continue
                codes = json.loads(meta.read_text("utf-8"))["exit_code_by_key"]
                for key, code in codes.items():
                    if patterns and not any(fnmatch.fnmatch(key, p) for p in patterns):
                        continue
                    status = status_by_exit_code[code]
                    diff = get_diff_for_mutant(key, path=rel) if status not in KILLED else ""
                    found[key] = (status, diff)
    finally:
        os.chdir(cwd)
    return found


def added_lines(diff: str) -> list[str]:
    return [ln[1:].strip() for ln in diff.splitlines() if ln.startswith("+") and not ln.startswith("+++")]


def summarise(name: str, found: dict, equivalents: list[dict], seconds: float) -> dict:
    """Counts, score and the survivors of one module run."""
    listed = {e["mutant"]: e for e in equivalents}
    killed = survived = 0
    survivors, equivalent, stale = [], [], []
    for key in sorted(found, key=lambda k: (k.rsplit("__mutmut_", 1)[0], int(k.rsplit("_", 1)[1]))):
        status, diff = found[key]
        entry = listed.get(key)
        if status in KILLED:
            killed += 1
            if entry:
                stale.append(key)
        elif entry and entry["line"].strip() in added_lines(diff):
            equivalent.append({"mutant": key, "reason": entry["reason"], "diff": diff})
        else:
            if entry:
                stale.append(key)
            survived += 1
            survivors.append({"mutant": key, "status": status, "diff": diff})
    scored = killed + survived
    return {
        "module": name,
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commit": git_commit(),
        "mutants": len(found),
        "killed": killed,
        "survived": survived,
        "equivalent": len(equivalent),
        "score": round(killed / scored, 4) if scored else None,
        "seconds": round(seconds, 1),
        "survivors": survivors,
        "equivalents": equivalent,
        "stale_equivalent_entries": stale,
    }


def tracked_at(rev: str, path: str) -> bool:
    """Whether ``path`` exists in git revision ``rev``."""
    out = subprocess.run(["git", "cat-file", "-e", f"{rev}:{path}"], cwd=REPO, capture_output=True)
    return out.returncode == 0


def git_commit() -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                           capture_output=True, text=True).stdout.strip()
    return out.stdout.strip() + ("+dirty" if dirty else "")


def table(results: dict) -> str:
    rows = ["# Mutation testing of the core modules", "",
            f"Tool: mutmut {results['tool_version']}; score = killed / (mutants − equivalent).", "",
            "| module | mutants | killed | survived | equivalent | score before | score after | run (s) |",
            "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, rec in results["modules"].items():
        after = rec.get("after") or rec["before"]
        pct = lambda r: "—" if r is None or r["score"] is None else f"{100 * r['score']:.1f} %"  # noqa: E731
        rows.append(f"| {name} | {after['mutants']} | {after['killed']} | {after['survived']} | "
                    f"{after['equivalent']} | {pct(rec['before'])} | {pct(rec.get('after'))} | {after['seconds']} |")
    for name, rec in results["modules"].items():
        after = rec.get("after") or rec["before"]
        if after["survivors"]:
            rows += ["", f"## {name}: surviving mutants", ""]
            for s in after["survivors"]:
                rows += [f"`{s['mutant']}` ({s['status']})", "", "```diff", s["diff"].strip(), "```", ""]
        if after["equivalents"]:
            rows += ["", f"## {name}: equivalent mutants", ""]
            rows += [f"- `{e['mutant']}`: {e['reason']}" for e in after["equivalents"]]
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--module", action="append", help="module name from modules.toml (repeatable); default all")
    parser.add_argument("--list", action="store_true", help="print the modules and their tests, then exit")
    parser.add_argument("--reset-baseline", action="store_true", help="record this run as the module's 'before'")
    parser.add_argument("--tests-at", metavar="REV",
                        help="use only the module's test files that exist at git REV (a 'before' run with "
                             "the tests of an earlier commit; implies --reset-baseline)")
    parser.add_argument("--rescore", action="store_true",
                        help="do not run mutmut: score the module's last run again (build/mutation/<module>) "
                             "against the current equivalent list; replaces its latest record")
    parser.add_argument("--output", type=Path, default=RESULTS / "mutation.json")
    args = parser.parse_args(argv)

    modules, equivalents = load_plan()
    if args.list:
        for name, spec in modules.items():
            print(f"{name}: {', '.join(spec['files'])}  <-  {', '.join(spec['tests'])}")
        return 0
    names = args.module or list(modules)
    unknown = [n for n in names if n not in modules]
    if unknown:
        parser.error(f"unknown module(s) {unknown}; known: {', '.join(modules)}")

    results = {"tool": "mutmut", "tool_version": mutmut_version(), "modules": {}}
    if args.output.exists():
        results["modules"] = json.loads(args.output.read_text("utf-8")).get("modules", {})
    for name in names:
        spec = modules[name]
        if args.tests_at:
            spec = dict(spec, tests=[t for t in spec["tests"] if tracked_at(args.tests_at, t)])
            args.reset_baseline = True
        patterns = list(spec.get("mutants", []))
        print(f"== {name}: {', '.join(spec['files'])} with {len(spec['tests'])} test file(s)", flush=True)
        record = results["modules"].get(name)
        if args.rescore:
            folder = SCRATCH / name
            if record is None or not (folder / "mutants").is_dir():
                parser.error(f"--rescore: no earlier run of {name} in {folder}")
            last = record.get("after") or record["before"]
            summary = summarise(name, collect(folder, spec, patterns), equivalents, last["seconds"])
            summary["date"], summary["commit"] = last["date"], last["commit"]
            summary["rescored"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
            record["after" if record.get("after") else "before"] = summary
        else:
            folder = prepare_scratch(name, spec)
            seconds = run_mutmut(folder, patterns)
            summary = summarise(name, collect(folder, spec, patterns), equivalents, seconds)
            if record is None or args.reset_baseline:
                results["modules"][name] = {"before": summary, "after": None}
            else:
                record["after"] = summary
        score = "—" if summary["score"] is None else f"{100 * summary['score']:.1f} %"
        print(f"   {summary['mutants']} mutants, {summary['killed']} killed, {summary['survived']} survived, "
              f"{summary['equivalent']} equivalent: score {score} in {summary['seconds']:.0f} s", flush=True)
        for key in summary["stale_equivalent_entries"]:
            print(f"   note: equivalent entry {key} no longer matches (killed or changed); update equivalent/{name}.toml")
        # another module's run may have written the file meanwhile: keep its records, replace ours
        if args.output.exists():
            on_disk = json.loads(args.output.read_text("utf-8")).get("modules", {})
            results["modules"] = {**on_disk, name: results["modules"][name]}
        atomic_write_json(args.output, results, mkdir=True)
        atomic_write_text(args.output.with_suffix(".md"), table(results), mkdir=True)
    print(f"results: {args.output} and {args.output.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
