"""Mutation testing of the guarantee's code with mutmut (``make mutate``, ``make mutate-ci``; docs/testing.md).

The code is split into groups, each a few modules with the test files that exercise them. A group runs in its own
scratch project ``mutants/<group>/`` (a copy of ``src/`` and ``tests/`` with its own ``[tool.mutmut]``), so mutmut
records, per mutated function, which of the group's tests reach it, and runs each mutant against those tests only
(stopping at the first failure). Verdicts are cached there: a second run only retries what changed.

    python tools/mutate.py run [GROUP ...]            # every mutant of the groups (default: all groups)
    python tools/mutate.py run decide evasion --sample 40 --seed 18 --fresh   # CI: a fixed, seeded sample
    python tools/mutate.py table [--strict]           # the table of docs/testing.md from the cached results
    python tools/mutate.py run --equivalents GROUP    # run the listed equivalents instead: none may be killed
    python tools/mutate.py review GROUP               # record the reviewed functions' hashes (after a re-review)

Exit status of ``run --sample`` (``--equivalents``): 1 if a sampled mutant survives (a listed equivalent is
killed). Reviewed equivalent mutants (``tools/mutation/<group>.toml``, with the group's modules and tests) are
counted apart, never run and never sampled — as long as their function is unchanged since the review (its hash
under ``[reviewed]``); otherwise they run and count like any mutant. Timeouts count as killed; "no tests" (no test
of the group reaches the function) as survived.
"""

from __future__ import annotations

import argparse
import ast
import hashlib
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


def _reviewed(group: str) -> dict[str, str]:
    """``{function: hash of its source text when its equivalents were reviewed}`` (``[reviewed]`` of the group's
    file, written by ``review``; see :func:`function_hashes`)."""
    spec = toml_loads((GROUP_DIR / f"{group}.toml").read_text(encoding="utf-8"))
    return dict(spec.get("reviewed", {}))


def _function(mutant: str) -> str:
    return mutant.rsplit("__mutmut_", 1)[0]


def function_hashes(root: Path, group: str) -> dict[str, str]:
    """``{function: hash of its source text}`` for the group's modules under ``root/src`` — every top-level function
    and method, named as mutmut names them (``safelane.mod.x_func``, ``safelane.mod.xǁClassǁmethod``; a nested
    function is part of the one around it). The text, not mutmut's own hash (of ``ast.dump``, which changes with the
    Python version), so the record holds across Pythons."""
    out = {}
    for module in GROUPS[group][0]:
        path = root / "src" / "safelane" / module
        if not path.exists():
            continue
        text = path.read_text(encoding="utf-8")
        prefix = "safelane." + module[:-3].replace("/", ".") + "."
        funcs = (ast.FunctionDef, ast.AsyncFunctionDef)
        for node in ast.parse(text).body:
            items = [(f"x_{node.name}", node)] if isinstance(node, funcs) else []
            if isinstance(node, ast.ClassDef):
                items = [(f"x\u01c1{node.name}\u01c1{m.name}", m) for m in node.body if isinstance(m, funcs)]
            for key, fn in items:
                digest = hashlib.sha256(ast.get_source_segment(text, fn).encode()).hexdigest()[:12]
                out[prefix + key] = digest
    return out


def stale_equivalents(work: Path, group: str) -> list[str]:
    """The group's listed equivalents whose function changed since the review (or was never recorded): mutmut
    numbers mutants per function, so after an edit the name may denote another mutant. They run like any other
    mutant until reviewed again."""
    now, then = function_hashes(work, group), _reviewed(group)
    return sorted(n for n in GROUPS[group][2] if (h := now.get(_function(n))) is None or h != then.get(_function(n)))


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


def run(groups: list[str], sample: int | None, seed: int, fresh: bool, children: int, check_eq: bool = False) -> int:
    eq = equivalents()
    bad = 0
    for group in groups:
        start, cpu = time.perf_counter(), _cpu_seconds()
        work = prepare(group, fresh, sample=bool(sample))
        every = mutant_names(work, group)
        stale = set(stale_equivalents(work, group))
        if stale:
            print(
                f"[{group}] {len(stale)} listed equivalents of functions changed since their review run as mutants "
                f"(re-review them, then `tools/mutate.py review {group}`): {', '.join(sorted(stale))}",
                flush=True,
            )
        if check_eq:
            bad += _check_equivalents(work, group, [n for n in every if n in eq], children, start, cpu)
            continue
        names = [n for n in every if n not in eq or n in stale]
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
    return 1 if bad and (sample or check_eq) else 0


def _check_equivalents(work: Path, group: str, listed: list[str], children: int, start: float, cpu: float) -> bool:
    """Run the group's listed equivalents themselves, each against every test that reaches it; True if one is
    killed (it is not equivalent)."""
    if listed:
        _mutmut(work, "run", "--max-children", str(children), *listed, capture_output=True)
    codes = results(work, group)
    killed = [n for n in listed if codes.get(n) in KILLED]
    took = f"{time.perf_counter() - start:.0f} s wall, {_cpu_seconds() - cpu:.0f} CPU s"
    print(f"[{group}] {len(listed)} listed equivalents run: {len(killed)} killed (not equivalent) in {took}")
    for name in killed:
        print(f"[{group}] KILLED, listed as equivalent: {name}", flush=True)
    return bool(killed)


def review(groups: list[str]) -> int:
    """Record, in each group's file, the hash of every function with listed equivalents as mutmut generated it
    last (``[reviewed]``, rewritten at the end of the file): run after reviewing the equivalents of changed
    functions."""
    for group in groups:
        now = function_hashes(ROOT, group)
        funcs = sorted({_function(n) for n in GROUPS[group][2]})
        missing = [f for f in funcs if f not in now]
        if missing:
            print(f"[{group}] functions with listed equivalents gone from the source: {', '.join(missing)}")
            return 1
        path = GROUP_DIR / f"{group}.toml"
        text = path.read_text(encoding="utf-8")
        text = text.split("\n[reviewed]\n", 1)[0].rstrip("\n")
        lines = [f"{json.dumps(f)} = {json.dumps(now[f])}" for f in funcs]
        path.write_text(text + "\n\n[reviewed]\n" + "\n".join(lines) + "\n", encoding="utf-8")
        print(f"[{group}] recorded the hashes of {len(funcs)} functions with listed equivalents")
    return 0


def table(strict: bool) -> int:
    eq = equivalents()
    rows = []
    for group, (modules, *_) in GROUPS.items():
        work = WORK / group
        stale = set(stale_equivalents(work, group)) if work.exists() else set()
        for module in modules:
            meta = work / "mutants" / "src" / "safelane" / (module + ".meta")
            codes = json.loads(meta.read_text())["exit_code_by_key"] if meta.exists() else {}
            n = len(codes)
            counted = {name for name in codes if name in eq and name not in stale}  # a stale entry counts as a mutant
            n_eq = len(counted)
            killed = sum(code in KILLED for name, code in codes.items() if name not in counted)
            survived = [name for name, code in codes.items() if name not in counted and code in SURVIVED]
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
    p_run.add_argument(
        "--equivalents",
        action="store_true",
        help="run the listed equivalents instead (exit 1 if one is killed: it is not equivalent)",
    )
    p_review = sub.add_parser("review", help="record the reviewed functions' hashes (after re-reviewing equivalents)")
    p_review.add_argument("groups", nargs="*")
    p_table = sub.add_parser("table")
    p_table.add_argument("--strict", action="store_true")
    args = parser.parse_args(argv)
    if args.command == "run":
        unknown = set(args.groups) - set(GROUPS)
        if unknown:
            parser.error(f"unknown group(s) {sorted(unknown)}; groups: {', '.join(GROUPS)}")
        return run(args.groups or list(GROUPS), args.sample, args.seed, args.fresh, args.children, args.equivalents)
    if args.command == "review":
        return review(args.groups or list(GROUPS))
    return table(args.strict)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
