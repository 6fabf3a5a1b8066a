"""The documentation's generated pages, from the code itself, so they cannot drift.

* :func:`model_file_reference`: every registered bond kind (``activebonds.bonds``), its
  bond-table keys, defaults, default search bounds, checks, flags and shared parameters;
* :func:`cli_reference`: every command of ``activebonds``, its arguments and options, from the
  click command behind the typer application.

MkDocs runs this file as a hook (``hooks:`` in mkdocs.yml): a page holding the line
``<!-- generated: model-file -->`` or ``<!-- generated: cli -->`` gets the text in its place.
The tests import it (tests/test_docs.py).
"""

from __future__ import annotations

import math

MARKERS = {
    "<!-- generated: model-file -->": "model_file_reference",
    "<!-- generated: cli -->": "cli_reference",
}

# file values at which a parameter's default search bounds are shown
SAMPLES = (0.0, 1.0, 10.0)


def _number(v) -> str:
    if v is None:
        return "required"
    if isinstance(v, float) and math.isfinite(v) and v == int(v) and abs(v) < 1e6:
        return str(int(v))
    return f"{v:g}"


def _bounds(p) -> str:
    if p.form == "constant":
        return "fixed (never searched)"
    shown = []
    for v in SAMPLES:
        try:
            lo, hi = p.bounds(v)
        except Exception:  # a bounds rule that refuses a sample value
            continue
        shown.append(f"{_number(v)} → [{_number(float(lo))}, {_number(float(hi))}]")
    return "; ".join(shown)


FORMS = {
    "scalar": "number or `{ value, min, max }`",
    "vector": "one number per axis (each fixed or `{ value, min, max }`)",
    "weights": "row over the kind's bonds (`weights = { part = [...] }`)",
    "constant": "D finite numbers, not zero (normalised when loaded)",
}


def _parameter_row(p) -> str:
    form = FORMS[p.form] + (f", part `{p.part}`" if p.part else "")
    when = f"bonds with `{p.when} = true`" if p.when else "every bond"
    check = f"must be {p.check.text}" if p.check else ""
    log = {True: "log", False: "linear", None: "file's choice"}[p.log]
    needs = f"; needs a `[{p.needs}]` table" if p.needs else ""
    return (
        f"| `{p.key}` | {form} | {_number(p.default)} | {_bounds(p)} | {check} | {log} | "
        f"{when}{needs} |"
    )


HEADER = (
    "| key | form | default | default search bounds (file value → [min, max]) | check "
    "| scaling | taken by |\n|---|---|---|---|---|---|---|"
)


def kind_section(kind) -> str:
    lines = [f"### `{kind.name}`", ""]
    if kind.what:
        lines.append(f"*{kind.what.capitalize()}.*")
        lines.append("")
    particles = "particle" if kind.arity == 1 else "particles"
    facts = [
        f'`kind = "{kind.name}"`, `particles` = {kind.arity} {particles}',
        "internal forces (sum to zero, no torque)" if kind.internal else "external forces",
    ]
    if kind.flags:
        facts.append("flags " + ", ".join(f"`{f} = true`" for f in kind.flags))
    if kind.off:
        facts.append(
            "may be `optional = true` (absent: " + ", ".join(f"`{f}`" for f in kind.off) + " = 0)"
        )
    if kind.timed:
        facts.append("forces depend on time")
    if kind.linear is not None:
        facts.append("enters the exact least squares (`--init lsq`)")
    if kind.mujoco is None or kind.mujoco.element is None:
        why = f": {kind.mujoco.why}" if kind.mujoco is not None and kind.mujoco.why else ""
        facts.append(f"not exported to MuJoCo{why}")
    else:
        facts.append(f"exported to MuJoCo as a {kind.mujoco.element}")
    lines += [f"- {f}" for f in facts]
    lines += ["", HEADER, *(_parameter_row(p) for p in kind.parameters)]
    if kind.shared:
        lines += [
            "",
            "Shared (model-level) parameters, one value for every bond that takes it:",
            "",
            HEADER,
            *(_parameter_row(p) for p in kind.shared),
        ]
    return "\n".join(lines)


def model_file_reference() -> str:
    """Markdown: one section per registered bond kind, in registration order."""
    from activebonds import bonds

    intro = (
        f"{len(bonds.names())} bond kinds are registered: "
        + ", ".join(f"`{n}`" for n in bonds.names())
        + ". Each `[[bond]]` table of a model file names its `kind`, its `particles` and, "
        "optionally, a `type` (bonds of one type share their parameters). A parameter is "
        "a number (fixed) or a table `{ value = V, min = A, max = B }` (free; `min`/`max` "
        "default to the bounds below, computed from the file value `V`)."
    )
    return "\n\n".join([intro, *(kind_section(k) for k in bonds.kinds())])


def _is_argument(param) -> bool:
    return param.param_type_name == "argument"


def _option_row(param) -> str:
    if _is_argument(param):
        name = f"`{param.name.upper()}`"
    else:
        name = ", ".join(f"`{o}`" for o in (*param.opts, *param.secondary_opts))
    kind = "flag" if getattr(param, "is_flag", False) else param.bare_type()
    if param.required:
        default = "required"
    elif getattr(param, "is_flag", False) or param.default in (None, ""):
        default = ""
    else:
        default = f"`{param.default}`"
    text = " ".join((getattr(param, "help", None) or "").split()).replace("|", "\\|")
    return f"| {name} | {kind} | {default} | {text} |"


def command_section(name: str, command) -> str:
    usage = " ".join(
        [f"activebonds {name}"]
        + [
            p.name.upper() if p.required else f"[{p.name.upper()}]"
            for p in command.params
            if _is_argument(p)
        ]
        + ["[OPTIONS]"]
    )
    doc = (command.help or "").strip()
    lines = [f"## `{name}`", "", f"```\n{usage}\n```", "", doc, ""]
    lines += ["| argument / option | type | default | meaning |", "|---|---|---|---|"]
    lines += [_option_row(p) for p in command.params if p.name not in ("help",)]
    lines.append("| `-h`, `--help` | flag | | Show the help and exit. |")
    return "\n".join(lines)


def commands() -> dict:
    """name -> click command, in the order of ``activebonds --help``."""
    from typer.main import get_command

    from activebonds.cli.main import app

    return dict(get_command(app).commands)


def cli_reference() -> str:
    listed = commands()
    intro = (
        f"`activebonds` has {len(listed)} commands: "
        + ", ".join(f"[`{n}`](#{n})" for n in listed)
        + ". `activebonds --version` prints the version; `activebonds COMMAND -h` prints a "
        "command's help. Bad input prints one line `error: ...` naming the file and the field "
        "and exits with code 2, writing nothing."
    )
    return "\n\n".join([intro, *(command_section(n, c) for n, c in listed.items())])


def on_page_markdown(markdown: str, page=None, config=None, files=None) -> str:
    """MkDocs hook: the generated text in place of its marker line."""
    for marker, function in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, globals()[function]())
    return markdown
