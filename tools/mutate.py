"""Mutation testing of the guarantee's code with mutmut (``make mutate``, ``make mutate-ci``; docs/testing.md).

The code is split into groups, each a few modules with the test files that exercise them. A group runs in its own
scratch project ``mutants/<group>/`` (a copy of ``src/`` and ``tests/`` with its own ``[tool.mutmut]``), so mutmut
records, per mutated function, which of the group's tests reach it, and runs each mutant against those tests only
(stopping at the first failure). Verdicts are cached there: a second run only retries what changed.

    python tools/mutate.py run [GROUP ...]            # every mutant of the groups (default: all groups)
    python tools/mutate.py run decide evasion --sample 40 --seed 18 --fresh   # CI: a fixed, seeded sample
    python tools/mutate.py table [--strict]           # the table of docs/testing.md from the cached results

Exit status of ``run --sample``: 1 if a sampled mutant survives. Reviewed equivalent mutants
(``tools/mutation/<group>.toml``, with the group's modules and tests) are counted apart and never sampled.
Timeouts count as killed; "no tests" (no test of the group reaches the function) as survived.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

try:
    from tomllib import loads as toml_loads
except ImportError:  # Python 3.10: mutmut brings `toml`
    from toml import loads as toml_loads

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / "mutants"

GROUP_DIR = ROOT / "tools" / "mutation"
#: Lines never mutated (mutmut's ``do_not_mutate_patterns``; the whole statement a matching line starts): raising
#: an error and warning. Their *conditions* are mutated like any other code; what is skipped is the exception's
#: class and message text, whose mutants (``"XX" + text + "XX"``) no ``pytest.raises(match=...)`` can tell apart.
#: The messages are tested by the bad-input tests, not by mutation.
DO_NOT_MUTATE = (r"^\s*raise\s", r"^\s*warnings\.warn\(")


def _groups() -> dict[str, tuple[tuple[str, ...], tuple[str, ...], dict[str, str]]]:
    """``{group: (modules under src/safelane, test files, {equivalent mutant: one-line argument})}`` from
    ``tools/mutation/<group>.toml``."""
    out = {}
    for path in sorted(GROUP_DIR.glob("*.toml")):
        spec = toml_loads(path.read_text(encoding="utf-8"))
        out[path.stem] = (tuple(spec["modules"]), tuple(spec["tests"]), dict(spec.get("equivalent", {})))
    return out


GROUPS = _groups()
KILLED = {1, 3, 36, 24, -24, 152, 255, 37}  # tests failed (or pytest errored), timed out, or type check caught it
SURVIVED = {0, 5, 33}  # tests passed, or no test reaches the function


def equivalents() -> dict[str, str]:
    """``{mutant name: one-line argument}``: the reviewed equivalent mutants of every group."""
    return {name: why for *_, eq in GROUPS.values() for name, why in eq.items()}


def _toml_list(values) -> str:
    return "[" + ", ".join(json.dumps(str(v)) for v in values) + "]"


def _env() -> dict:
    return {**os.environ, "HYPOTHESIS_PROFILE": "ci"}


def prepare(group: str, fresh: bool, sample: bool = False) -> Path:
    """The group's scratch project (``mutants/<group>``, or ``mutants/<group>-sample`` for a sample, so that CI's
    sample never touches ``make mutate``'s cache): a fresh copy of src/ and tests/, its pyproject (the
    repository's pytest settings, the group's mutmut settings). Cached verdicts stay unless ``fresh``."""
    modules, tests, _ = GROUPS[group]
    work = WORK / (f"{group}-sample" if sample else group)
    if fresh:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    for part in ("src", "tests"):
        shutil.rmtree(work / part, ignore_errors=True)
        shutil.copytree(ROOT / part, work / part, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    pytest_ini = toml_loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    lines = ["[tool.pytest.ini_options]"]
    lines += [f"{k} = {_toml_list(v) if isinstance(v, list) else json.dumps(v)}" for k, v in pytest_ini.items()]
    lines += ["", "[tool.mutmut]", 'source_paths = ["src/safelane"]',
              f"only_mutate = {_toml_list('src/safelane/' + m for m in modules)}",
              'pytest_add_cli_args = ["-p", "no:cacheprovider"]',
              f"pytest_add_cli_args_test_selection = {_toml_list(tests)}",
              f"do_not_mutate_patterns = {_toml_list(DO_NOT_MUTATE)}",
              "use_git_change_detection = false"]  # fmt: skip
    (work / "pyproject.toml").write_text("\n".join(lines) + "\n")
    return work


def mutant_names(work: Path, group: str) -> list[str]:
    """Every mutant name of the group (mutmut's generation step alone, in a child process)."""
    code = (
        "import os; os.chdir(os.environ['WORK']);"
        "from mutmut.__main__ import copy_src_dir, copy_also_copy_files, create_mutants;"
        "os.makedirs('mutants', exist_ok=True); copy_src_dir(); copy_also_copy_files(); create_mutants(2)"
    )
    subprocess.run([sys.executable, "-c", code], check=True, env={**_env(), "WORK": str(work)},
                   stdout=subprocess.DEVNULL)  # fmt: skip
    return sorted(results(work, group))


def results(work: Path, group: str) -> dict[str, int | None]:
    codes = {}
    for module in GROUPS[group][0]:
        meta = work / "mutants" / "src" / "safelane" / (module + ".meta")
        if meta.exists():
            codes |= json.loads(meta.read_text())["exit_code_by_key"]
    return codes


def _mutmut(work: Path, *args: str, **kw) -> subprocess.CompletedProcess:
    mutmut = Path(sys.executable).with_name("mutmut")
    return subprocess.run([str(mutmut), *args], cwd=work, env=_env(), text=True, **kw)


def _cpu_seconds() -> float:
    """CPU time (user + system) of this process and every finished child process (mutmut and the pytest processes
    it forked and waited for). On a machine shared with other work the wall time inflates; the CPU time does not:
    CPU seconds / cores is what the run costs on an idle machine."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def run(groups: list[str], sample: int | None, seed: int, fresh: bool, children: int) -> int:
    eq = equivalents()
    bad = 0
    for group in groups:
        start, cpu = time.perf_counter(), _cpu_seconds()
        work = prepare(group, fresh, sample=bool(sample))
        names = [n for n in mutant_names(work, group) if n not in eq]
        chosen = sorted(random.Random(seed).sample(names, min(sample, len(names)))) if sample else []
        what = f"{len(chosen)} sampled (seed {seed}) of" if sample else "all"
        print(f"[{group}] {what} {len(names)} non-equivalent mutants of {', '.join(GROUPS[group][0])}", flush=True)
        # Name the mutants to run: mutmut would otherwise also run the reviewed equivalents, each against every test
        # that reaches its function (they cannot fail, so nothing stops early). Named mutants are re-run even when
        # cached, so only those without a verdict are named.
        codes = results(work, group)
        pending = chosen or [n for n in names if codes.get(n) is None]
        proc = _mutmut(work, "run", "--max-children", str(children), *pending, capture_output=True) if pending else None
        codes = results(work, group)
        # Survivors cached by an earlier run are not retried by mutmut unless named: retry them against today's tests
        # (not those this run just found).
        tried = set(pending)
        retry = [n for n in names if codes.get(n) in SURVIVED and n not in tried] if not sample else []
        if retry:
            proc = _mutmut(work, "run", "--max-children", str(children), *retry, capture_output=True)
            codes = results(work, group)
        checked = chosen or names
        survivors = [n for n in checked if codes.get(n) not in KILLED]
        print(f"[{group}] killed {len(checked) - len(survivors)} of {len(checked)} in "
              f"{time.perf_counter() - start:.0f} s wall, {_cpu_seconds() - cpu:.0f} CPU s", flush=True)  # fmt: skip
        if survivors:
            bad += 1
            if proc is not None and all(codes.get(n) is None for n in survivors):
                print(proc.stdout[-3000:], proc.stderr[-3000:], sep="\n")
            for name in survivors:
                diff = _mutmut(work, "show", name, capture_output=True).stdout
                print(f"[{group}] SURVIVED (exit code {codes.get(name)}): {name}\n{diff}", flush=True)
    return 1 if bad and sample else 0


def table(strict: bool) -> int:
    eq = equivalents()
    rows = []
    for group, (modules, *_) in GROUPS.items():
        work = WORK / group
        for module in modules:
            meta = work / "mutants" / "src" / "safelane" / (module + ".meta")
            codes = json.loads(meta.read_text())["exit_code_by_key"] if meta.exists() else {}
            n = len(codes)
            n_eq = sum(name in eq for name in codes)
            killed = sum(code in KILLED for name, code in codes.items() if name not in eq)
            survived = [name for name, code in codes.items() if name not in eq and code in SURVIVED]
            rows.append((module, n, killed, n_eq, survived, n - n_eq - killed - len(survived)))
    print("| module | mutants | killed | equivalent | survived | not run | killed / non-equivalent |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    failing = False
    for module, n, killed, n_eq, survived, unchecked in rows:
        if n == 0:
            print(f"| `{module}` | – | – | – | – | – | not run (`tools/mutate.py run GROUP`) |")
            failing = True
            continue
        score = killed / max(n - n_eq, 1)
        print(f"| `{module}` | {n} | {killed} | {n_eq} | {len(survived)} | {unchecked} | {100 * score:.1f} % |")
        core = module.startswith(("safety/", "shield/"))
        failing |= bool(survived or unchecked) if core else score < 0.9
    for *_, survived, _ in rows:
        for name in survived:
            print(f"survived: {name}")
    return 1 if strict and failing else 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run")
    p_run.add_argument("groups", nargs="*", help=f"of: {', '.join(GROUPS)}")
    p_run.add_argument("--sample", type=int, default=None)
    p_run.add_argument("--seed", type=int, default=18)
    p_run.add_argument("--fresh", action="store_true", help="drop the cached verdicts first")
    p_run.add_argument("--children", type=int, default=2, help="parallel mutants (default 2)")
    p_table = sub.add_parser("table")
    p_table.add_argument("--strict", action="store_true")
    args = parser.parse_args(argv)
    if args.command == "run":
        unknown = set(args.groups) - set(GROUPS)
        if unknown:
            parser.error(f"unknown group(s) {sorted(unknown)}; groups: {', '.join(GROUPS)}")
        return run(args.groups or list(GROUPS), args.sample, args.seed, args.fresh, args.children)
    return table(args.strict)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
