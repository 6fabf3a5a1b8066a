"""Where the time of one generation goes, for the paper's horse (pop 500, neural).

    python benchmarks/profile.py [--population 500] [--bonds neural] [--chunk 200] [--top 15]
                                 [--json out.json] [--trace-dir DIR]

Two independent views:

1. Ablation (robust): the steady-state time of one generation with the real cost, with a trivial
   cost of the same shapes (-> the ES operators' own time), and of the vmapped cost alone over the
   same population (-> the cost's time).
2. Trace: ``jax.profiler.start_trace/stop_trace`` around jitted chunks; the events of the trace
   (gzip JSON, ph == "X") are summed by name and divided by the number of generations, and each
   HLO instruction is mapped through the compiled module's text
   (``jitted.lower(...).compile().as_text()``) to its op_name and to the source line that made it
   (stack-frame tables of the HLO text). Categories (RNG, crossover, mutation, cost evaluation,
   selection, history row, other) come from that source location: the package function, or, for
   es.generation itself, its numbered sections. A fusion is attributed to the category of its
   root instruction; the other categories it fuses are listed. Thread time is summed, so with
   intra-op parallelism on 2 cores the sum may exceed the wall time.
"""

from __future__ import annotations

import argparse
import ast
import collections
import glob
import gzip
import json
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import problems as P  # noqa: E402  (imports activebonds: XLA flags, float64)
from activebonds.identify.search import es  # noqa: E402
from run import F64, Ours, _cast  # noqa: E402

now = time.perf_counter

CATEGORIES = (
    "RNG",
    "crossover",
    "mutation",
    "cost evaluation",
    "selection",
    "history row",
    "loop bookkeeping",
    "other",
)
_BY_FUNCTION = {
    "tournament": "crossover",
    "local_tournament": "crossover",
    "crossover": "crossover",
    "crossover_weights": "crossover",
    "mutate": "mutation",
    "reflect": "mutation",
    "group_bias": "mutation",
    "choose": "mutation",
    "select": "selection",
    "noise": "RNG",
    "draw": "RNG",
    "streams": "RNG",
}
_COST_FILES = ("cost.py", "forces.py", "integrate.py", "layout.py", "params.py")
_COST_FILES += ("accumulate.py", "unary.py", "binary.py", "ternary.py")  # activebonds/bonds


# ---------------------------------------------------------------------------------------------
# ablation


def per_generation(runner, min_s: float) -> float:
    times = []
    while sum(times) < min_s or len(times) < 2:
        times.append(runner.call())
    return statistics.median(times) / runner.block


def trivial_bench(bench):
    """The same problem with a cost of the same shapes that costs nothing."""
    n_particles = bench.model.topology.n_particles
    mid = 0.5 * (bench.problem.lower + bench.problem.upper)

    def cheap(genome):
        c = jnp.sum(jnp.square(genome - mid))
        return c, jnp.full((n_particles,), c / n_particles)

    ident = bench.ident
    problem = ident.problem._replace(evaluate=cheap)
    return P.Bench(
        bench.name + " (trivial cost)",
        type(ident)(ident.model, ident.data, ident.windows, problem),
        bench.settings,
        bench.description,
    )


class CostOnly:
    """The vmapped cost alone: ``block`` evaluations of the whole population per call (one
    lax.scan, the genomes nudged each step so nothing is hoisted)."""

    def __init__(self, bench, population, block):
        self.block = block
        cost = jax.vmap(_cast(bench.problem.evaluate))
        lo, hi = jnp.asarray(bench.problem.lower), jnp.asarray(bench.problem.upper)
        genes = lo + (hi - lo) * jax.random.uniform(
            jax.random.PRNGKey(1), (population, len(lo)), F64
        )

        def many(genes):
            def body(acc, i):
                c, _ = cost(genes + 1e-12 * i.astype(F64))
                return acc + jnp.sum(jnp.where(jnp.isfinite(c), c, 0.0)), None

            return jax.lax.scan(body, jnp.zeros((), F64), jnp.arange(block))[0]

        self.genes = genes
        self.fn = jax.jit(many).lower(genes).compile()

    def call(self):
        t = now()
        jax.block_until_ready(self.fn(self.genes))
        return now() - t


def ablation(bench, population, chunk, min_s, repeats=3) -> dict:
    """The three timings interleaved ``repeats`` times (noisy shared machine); medians."""
    runners = {
        "real": Ours(bench, population, chunk),
        "trivial": Ours(trivial_bench(bench), population, chunk),
        "cost": CostOnly(bench, population, chunk),
    }
    times = {k: [] for k in runners}
    for r in runners.values():
        r.call()
    for _ in range(repeats):
        for k, r in runners.items():
            times[k].append(per_generation(r, min_s / repeats))
    real, trivial, cost = (statistics.median(times[k]) for k in ("real", "trivial", "cost"))
    return {
        "generation_us": real * 1e6,
        "operators_us": trivial * 1e6,  # the ES with a free cost
        "cost_us": cost * 1e6,  # the vmapped cost alone
        "cost_share": cost / real,
        "operator_share": trivial / real,
        "unexplained_us": (real - trivial - cost) * 1e6,
        "samples_us": {k: [round(x * 1e6, 1) for x in v] for k, v in times.items()},
    }


# ---------------------------------------------------------------------------------------------
# HLO text: instruction -> (op_name, source location)

_INSTR = re.compile(r"^\s*(?:ROOT\s+)?%([\w.\-]+)\s*=\s*(.*)$")
_COMP = re.compile(r"^(?:ENTRY\s+)?%([\w.\-]+)\s*\(.*\{\s*$")


def _table(lines, start):
    out = {}
    for line in lines[start + 1 :]:
        m = re.match(r"^\s*(\d+)\s+(.*)$", line)
        if not m:
            break
        out[int(m.group(1))] = m.group(2).strip()
    return out


def _chain(frame_id, frames, locs, files, funcs) -> list[tuple[str, str, int]]:
    """Source locations (file, function, line) from the op's own frame up to the outermost.

    In the HLO text's StackFrames table (jax 0.10 / XLA), a frame's printed
    ``parent_frame_id`` is the parent's 1-based index plus one (1 = no parent): read that way,
    every chain runs op -> helper -> operator -> PaperES.ask/tell -> evolve.step -> evolve.chunk
    -> caller."""
    out, seen = [], set()
    while frame_id in frames and frame_id not in seen and len(out) < 64:
        seen.add(frame_id)
        loc = locs.get(frames[frame_id].get("file_location_id"), {})
        out.append(
            (
                files.get(loc.get("file_name_id"), "?"),
                funcs.get(loc.get("function_name_id"), "?"),
                loc.get("line", 0),
            )
        )
        frame_id = frames[frame_id].get("parent_frame_id", 0) - 1
    return out


def parse_hlo(text: str) -> dict:
    lines = text.splitlines()
    heads = {
        line.strip(): i
        for i, line in enumerate(lines)
        if line.strip() in ("FileNames", "FunctionNames", "FileLocations", "StackFrames")
    }
    files = (
        {k: v.strip('"') for k, v in _table(lines, heads["FileNames"]).items()}
        if "FileNames" in heads
        else {}
    )
    funcs = (
        {k: v.strip('"') for k, v in _table(lines, heads["FunctionNames"]).items()}
        if "FunctionNames" in heads
        else {}
    )

    def fields(s):
        return {k: int(v) for k, v in re.findall(r"(\w+)=(-?\d+)", s)}

    locs = (
        {k: fields(v) for k, v in _table(lines, heads["FileLocations"]).items()}
        if "FileLocations" in heads
        else {}
    )
    frames = (
        {k: fields(v) for k, v in _table(lines, heads["StackFrames"]).items()}
        if "StackFrames" in heads
        else {}
    )

    instrs, comps, comp = {}, collections.defaultdict(list), None
    for line in lines:
        m = _COMP.match(line)
        if m and not line.startswith(" "):
            comp = m.group(1)
            continue
        m = _INSTR.match(line)
        if not m:
            continue
        name, rest = m.groups()
        op = re.search(r'op_name="([^"]*)"', rest)
        sf = re.search(r"stack_frame_id=(\d+)", rest)
        calls = re.search(r"calls=%([\w.\-]+)", rest)
        opcode = re.search(r"(?<![\w.%\-])([a-z][a-z0-9\-]*)\(", rest)
        chain = _chain(int(sf.group(1)), frames, locs, files, funcs) if sf else []
        info = {
            "op_name": op.group(1) if op else "",
            "src": chain[0] if chain else None,
            "chain": chain,
            "calls": calls.group(1) if calls else None,
            "opcode": opcode.group(1) if opcode else "",
            "computation": comp,
        }
        instrs[name] = info
        comps[comp].append(name)
    return {"instructions": instrs, "computations": comps}


# ---------------------------------------------------------------------------------------------
# categories from source locations


def _generation_sections() -> list[tuple[int, str]]:
    """(first line, category) of the numbered sections of PaperES.ask and PaperES.tell and
    of the history row."""
    path = Path(es.__file__)
    source = path.read_text()
    tree = ast.parse(source)
    lines = source.splitlines()
    marks = []
    names = {"1": "crossover", "2": "mutation", "3": "cost evaluation", "4": "selection"}
    for fn in ast.walk(tree):
        if not (isinstance(fn, ast.FunctionDef) and fn.name in ("ask", "tell")):
            continue
        marks.append((fn.lineno, "other"))
        for i in range(fn.lineno, fn.end_lineno + 1):
            text = lines[i - 1].strip()
            m = re.match(r"#\s*(\d)\.", text)
            if m and m.group(1) in names:
                marks.append((i, names[m.group(1)]))
            if re.match(r"(finite|ordered|row)\s*=", text) and marks[-1][1] != "history row":
                marks.append((i, "history row"))
    return sorted(marks)


_SECTIONS = None


def _frame_category(src) -> str | None:
    """The category of one source location, or None if it says nothing (a helper)."""
    global _SECTIONS
    file, func, line = src
    base = Path(file).name
    top = func.split(".<locals>")[0].split(".")[-1]
    if base == "rng.py":
        return "RNG"
    if base in _COST_FILES or top in ("_evaluate", "cost", "predict", "make_cost"):
        return "cost evaluation"
    if base in ("operators.py", "es.py") and top in _BY_FUNCTION:
        return _BY_FUNCTION[top]
    if base == "evolve.py" and top in ("population_evaluate", "evaluate"):
        return "cost evaluation"
    if base == "evolve.py" and top in ("chunk", "body"):
        return "loop bookkeeping"  # the scan body: the stop mask over the state
    if base == "es.py" and top in ("ask", "tell"):
        if _SECTIONS is None:
            _SECTIONS = _generation_sections()
        cat = "other"
        for start, name in _SECTIONS:
            if line >= start:
                cat = name
        return cat
    return None


def category(chain) -> str:
    """The first frame, from the op up, that names a category (helpers such as _top_k or
    _index take their caller's)."""
    if chain and isinstance(chain[0], str):
        chain = [chain]  # a single location
    for src in chain or ():
        cat = _frame_category(src)
        if cat is not None:
            return cat
    return "other"


def _where(chain) -> str:
    """'file:line function' of the op, and of the caller that gave its category if the op is
    in a helper."""
    if not chain:
        return ""
    text = f"{Path(chain[0][0]).name}:{chain[0][2]} {chain[0][1]}"
    if _frame_category(chain[0]) is None:
        caller = next((c for c in chain[1:] if _frame_category(c) is not None), None)
        if caller:
            text += f" <- {Path(caller[0]).name}:{caller[2]} {caller[1]}"
    return text


def fused_categories(hlo, name) -> collections.Counter:
    info = hlo["instructions"].get(name)
    out = collections.Counter()
    if not info or not info["calls"]:
        return out
    for sub in hlo["computations"].get(info["calls"], []):
        si = hlo["instructions"][sub]
        if si["src"] is not None and si["opcode"] not in ("parameter", "constant", "bitcast"):
            out[category(si["chain"])] += 1
    return out


# ---------------------------------------------------------------------------------------------
# trace


def trace(runner, n_calls: int, trace_dir: str) -> tuple[dict, dict, float]:
    """Sum of event durations (µs) by name over ``n_calls`` chunks; counts; wall seconds."""
    runner.call()
    jax.profiler.start_trace(trace_dir)
    t = now()
    for _ in range(n_calls):
        runner.call()
    wall = now() - t
    jax.profiler.stop_trace()
    files = sorted(glob.glob(f"{trace_dir}/**/*.trace.json.gz", recursive=True))
    if not files:
        raise RuntimeError(f"no *.trace.json.gz under {trace_dir}")
    data = json.load(gzip.open(files[-1]))
    events = data["traceEvents"] if isinstance(data, dict) else data
    dur, count = collections.Counter(), collections.Counter()
    for e in events:
        if e.get("ph") == "X":
            dur[e["name"]] += float(e.get("dur", 0.0))
            count[e["name"]] += 1
    return dur, count, wall


def profile_trace(bench, population, chunk, n_calls, top, trace_dir) -> dict:
    runner = Ours(bench, population, chunk)
    hlo = parse_hlo(runner.run_c.as_text())
    dur, count, wall = trace(runner, n_calls, trace_dir)
    gens = chunk * n_calls
    containers = ("while", "call", "conditional")
    rows = []
    for name, total in dur.items():
        info = hlo["instructions"].get(name)
        if info is None or info["opcode"] in containers or name.startswith(containers):
            continue  # Python-side events, executor wrappers, loop containers
        cat = category(info["chain"])
        fused = fused_categories(hlo, name)
        also = sorted(c for c in fused if c != cat)
        rows.append(
            {
                "name": name,
                "us_per_generation": total / gens,
                "calls_per_generation": count[name] / gens,
                "category": cat,
                "also_fuses": also,
                "op_name": info["op_name"],
                "source": _where(info["chain"]),
            }
        )
    rows.sort(key=lambda r: -r["us_per_generation"])
    total_ops = sum(r["us_per_generation"] for r in rows)
    by_cat = collections.Counter()
    for r in rows:
        by_cat[r["category"]] += r["us_per_generation"]
    return {
        "generations": gens,
        "wall_us_per_generation": wall / gens * 1e6,
        "op_time_us_per_generation": total_ops,
        "top": rows[:top],
        "n_instructions": len(rows),
        "by_category": {c: by_cat.get(c, 0.0) for c in CATEGORIES},
    }


# ---------------------------------------------------------------------------------------------


def print_profile(result: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=170)
    a = result["ablation"]
    console.print(
        f"[bold]{result['config']}[/bold], pop {result['population']}: one generation "
        f"{a['generation_us']:.0f} µs (ablation, steady state)"
    )
    t = Table(title="Ablation")
    for c in ("part", "µs / generation", "share of a generation"):
        t.add_column(c, justify="left" if c == "part" else "right")
    t.add_row("whole generation (real cost)", f"{a['generation_us']:.0f}", "100 %")
    t.add_row(
        "ES operators (same generation, trivial cost)",
        f"{a['operators_us']:.0f}",
        f"{100 * a['operator_share']:.0f} %",
    )
    t.add_row(
        f"vmapped cost alone ({result['population']} evaluations)",
        f"{a['cost_us']:.0f}",
        f"{100 * a['cost_share']:.0f} %",
    )
    t.add_row("rest (real - operators - cost)", f"{a['unexplained_us']:.0f}", "")
    console.print(t)

    tr = result["trace"]
    t = Table(
        title=f"Trace: top {len(tr['top'])} HLO ops by summed thread time "
        f"({tr['generations']} generations; wall {tr['wall_us_per_generation']:.0f} µs/gen, "
        f"ops {tr['op_time_us_per_generation']:.0f} µs/gen summed over threads)"
    )
    for c in ("op", "µs/gen", "%", "runs/gen", "category", "also fuses", "op_name", "source"):
        t.add_column(c, justify="right" if c in ("µs/gen", "%", "runs/gen") else "left")
    total = tr["op_time_us_per_generation"] or 1.0
    for r in tr["top"]:
        t.add_row(
            r["name"],
            f"{r['us_per_generation']:.1f}",
            f"{100 * r['us_per_generation'] / total:.1f}",
            f"{r['calls_per_generation']:.2f}",
            r["category"],
            ", ".join(r["also_fuses"]),
            r["op_name"].replace("jit(run)/", "")[-60:],
            r["source"],
        )
    console.print(t)
    t = Table(title="Trace: summary by category (root op of each fusion)")
    for c in ("category", "µs/gen", "%"):
        t.add_column(c, justify="left" if c == "category" else "right")
    for c, us in sorted(tr["by_category"].items(), key=lambda kv: -kv[1]):
        t.add_row(c, f"{us:.1f}", f"{100 * us / total:.1f}")
    console.print(t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=500)
    ap.add_argument("--bonds", default="neural", choices=("standard", "neural"))
    ap.add_argument("--chunk", type=int, default=200)
    ap.add_argument("--calls", type=int, default=3, help="chunks traced")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--min-s", type=float, default=1.5, help="seconds per ablation timing")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--trace-dir")
    args = ap.parse_args(argv)
    bench = P.paper_horse(args.bonds)
    result = {"config": bench.name, "population": args.population, "chunk": args.chunk}
    result["ablation"] = ablation(bench, args.population, args.chunk, args.min_s)
    trace_dir = args.trace_dir or tempfile.mkdtemp(prefix="activebonds-trace-")
    result["trace"] = profile_trace(
        bench, args.population, args.chunk, args.calls, args.top, trace_dir
    )
    result["trace_dir"] = trace_dir
    print_profile(result)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
