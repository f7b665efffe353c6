"""The documentation stays inside the repository and its links resolve.

How this works: every file the repository holds (``git ls-files``, untracked files included, or
a walk of the folders when there is no git checkout) under README.md, docs/, skeye/, tests/,
examples/ and benchmarks/ is searched for references to documents that live outside the
repository (the old specification folder and its file names). Every markdown link in README.md
and docs/**/*.md is resolved: a relative target must be a file or folder inside the repository,
and a ``#anchor`` into a markdown file must name one of its headings (GitHub's slug rules).
Every import of skeye in a ``python`` code block of those files must name a module and names
that exist (resolved in a child process, so this one loads no simulator). The checkers are
plain functions, tested here on small files too, so the test can fail.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKED = ("README.md", "docs", "skeye", "tests", "examples", "benchmarks")

# Documents a user of the project does not have. Spelled in pieces so this file does not match.
OUTSIDE_REFERENCES = (
    "../" + "shared",
    "shared" + "/spec",
    "/work" + "/",
    *(
        name + ".md"
        for name in (
            "SIM_" + "PROTOCOL",
            "IMAGE_" + "PROTOCOL",
            "PILOT_" + "PACKETS",
            "LANDING_" + "PAD",
            "EXPERI" + "MENTS",
            "ARCHI" + "TECTURE",
            "STY" + "LE",
        )
    ),
)

_FENCE = re.compile(r"^\s*(```|~~~)")
_INLINE_CODE = re.compile(r"`+[^`]*`+")
_LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$")
_HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
_HTML_ANCHOR = re.compile(r"<a\s+(?:id|name)=\"([^\"]+)\"", re.IGNORECASE)
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")
_CODE_FENCE = re.compile(r"^\s*(?:```|~~~)\s*([\w+-]*)")
_SKEYE_IMPORT = re.compile(
    r"^\s*(?:from\s+(skeye(?:\.\w+)*)\s+import\s+(.+)|import\s+(skeye(?:\.\w+)*)\b)")


def repo_files(root: Path = ROOT) -> list[Path]:
    """The files of the repository under the checked paths (tracked and untracked, not ignored)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-co", "--exclude-standard", "--", *CHECKED],
            cwd=root, capture_output=True, text=True, check=True, timeout=60,
        ).stdout
        files = [root / line for line in out.splitlines() if line]
    except (OSError, subprocess.SubprocessError):
        files = []
        for top in CHECKED:
            base = root / top
            if base.is_file():
                files.append(base)
            elif base.is_dir():
                files.extend(p for p in base.rglob("*") if p.is_file()
                             and "__pycache__" not in p.parts)
    return [f for f in files if f.is_file()]


def text_of(path: Path) -> str | None:
    """The file as UTF-8 text, or None for a binary file."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return None


def outside_references(text: str) -> list[tuple[int, str]]:
    """(line number, reference) for every mention of a document outside the repository."""
    found: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        for ref in OUTSIDE_REFERENCES:
            if ref in line:
                found.append((number, ref))
    return found


def slug(heading: str, seen: dict[str, int]) -> str:
    """GitHub's anchor for a heading's text; ``seen`` numbers repeats (-1, -2, ...)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link reads as its text
    text = re.sub(r"[^\w\- ]", "", text.strip().lower())
    base = text.replace(" ", "-")
    count = seen.get(base, 0)
    seen[base] = count + 1
    return base if count == 0 else f"{base}-{count}"


def anchors(text: str) -> set[str]:
    """Every anchor a markdown text defines: heading slugs and HTML ``<a id=...>``."""
    out: set[str] = set()
    seen: dict[str, int] = {}
    in_code = False
    for line in text.splitlines():
        if _FENCE.match(line):
            in_code = not in_code
            continue
        if in_code:
            continue
        match = _HEADING.match(line)
        if match:
            out.add(slug(match.group(2), seen))
        out.update(_HTML_ANCHOR.findall(line))
    return out


def links(text: str) -> list[tuple[int, str]]:
    """(line number, target) of every markdown link and image outside code."""
    found: list[tuple[int, str]] = []
    in_code = False
    for number, line in enumerate(text.splitlines(), start=1):
        if _FENCE.match(line):
            in_code = not in_code
            continue
        if in_code:
            continue
        plain = _INLINE_CODE.sub("", line)
        found.extend((number, target) for target in _LINK.findall(plain))
        ref = _REF_DEF.match(plain)
        if ref:
            found.append((number, ref.group(1)))
    return found


def broken_links(path: Path, root: Path = ROOT) -> list[str]:
    """What is wrong with the links of one markdown file (empty when all resolve)."""
    text = path.read_text(encoding="utf-8")
    problems: list[str] = []
    for number, target in links(text):
        where = f"{path.relative_to(root)}:{number}: {target}"
        if _SCHEME.match(target):
            if target.lower().startswith(("http://", "https://", "mailto:")):
                continue
            problems.append(f"{where}: links outside the repository")
            continue
        file_part, _, anchor = target.partition("#")
        if file_part.startswith("/"):
            problems.append(f"{where}: absolute path (links outside the repository)")
            continue
        resolved = (path.parent / file_part).resolve() if file_part else path.resolve()
        if not resolved.is_relative_to(root.resolve()):
            problems.append(f"{where}: points outside the repository")
            continue
        if not resolved.exists():
            problems.append(f"{where}: no such file")
            continue
        if anchor and resolved.suffix == ".md" and resolved.is_file():
            if anchor not in anchors(resolved.read_text(encoding="utf-8")):
                problems.append(f"{where}: no heading with anchor #{anchor}")
    return problems


def python_imports(text: str) -> list[tuple[int, str, tuple[str, ...]]]:
    """(line number, module, names taken) of every import of skeye in a python code block."""
    found: list[tuple[int, str, tuple[str, ...]]] = []
    language: str | None = None  # the open block's language; None outside code
    for number, line in enumerate(text.splitlines(), start=1):
        fence = _CODE_FENCE.match(line)
        if fence:
            language = fence.group(1).lower() if language is None else None
            continue
        match = _SKEYE_IMPORT.match(line) if language in ("python", "py") else None
        if match is None:
            continue
        if match.group(3):
            found.append((number, match.group(3), ()))
            continue
        names = match.group(2).split("#")[0].strip().strip("()")
        found.append((number, match.group(1), tuple(
            part.split(" as ")[0].strip() for part in names.split(",") if part.strip())))
    return found


_RESOLVE = """
import importlib, json, sys
problems = []
for where, module, names in json.loads(sys.stdin.read()):
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        problems.append(f"{where}: cannot import {module}: {exc}")
        continue
    for name in names:
        if hasattr(mod, name):
            continue
        try:
            importlib.import_module(f"{module}.{name}")
        except ImportError:
            problems.append(f"{where}: {module} has no {name}")
print(json.dumps(problems))
"""


def unresolved_imports(imports: list[tuple[str, str, tuple[str, ...]]],
                       root: Path = ROOT) -> list[str]:
    """What is wrong with (where, module, names) imports, resolved in a child process."""
    done = subprocess.run([sys.executable, "-c", _RESOLVE], input=json.dumps(imports),
                          capture_output=True, text=True, cwd=root, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def markdown_docs(root: Path = ROOT) -> list[Path]:
    return [p for p in repo_files(root)
            if p.suffix == ".md" and (p == root / "README.md" or p.is_relative_to(root / "docs"))]


# --- the repository -----------------------------------------------------------------------


def test_nothing_refers_outside_the_repository():
    this_file = Path(__file__).resolve()
    problems: list[str] = []
    files = repo_files()
    assert any(p.name == "sim_lines.py" for p in files), "the file list is empty or wrong"
    for path in files:
        if path.resolve() == this_file:
            continue
        text = text_of(path)
        if text is None:
            continue
        problems.extend(
            f"{path.relative_to(ROOT)}:{n}: refers to {ref!r}"
            for n, ref in outside_references(text)
        )
    assert not problems, "references to documents outside the repository:\n" + "\n".join(problems)


def test_markdown_links_resolve():
    docs = markdown_docs()
    assert ROOT / "README.md" in docs and ROOT / "docs" / "README.md" in docs
    problems = [problem for path in docs for problem in broken_links(path)]
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_python_examples_import_what_exists():
    imports = [(f"{path.relative_to(ROOT)}:{number}", module, names)
               for path in markdown_docs()
               for number, module, names in python_imports(path.read_text(encoding="utf-8"))]
    assert any(module == "skeye.vision.calibration" for _, module, _ in imports)
    problems = unresolved_imports(imports)
    assert not problems, "examples importing what skeye does not have:\n" + "\n".join(problems)


@pytest.mark.parametrize(
    "page",
    [
        "protocols/simulator.md",
        "protocols/images.md",
        "protocols/packets.md",
        "landing-pad.md",
        "experiments.md",
    ],
)
def test_protocol_pages_exist_and_are_indexed(page):
    assert (ROOT / "docs" / page).is_file()
    index = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    assert f"]({page})" in index, f"docs/README.md does not link {page}"


def test_every_docs_page_is_indexed():
    index = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    linked = {target.partition("#")[0] for _, target in links(index)}
    pages = {
        p.relative_to(ROOT / "docs").as_posix()
        for p in markdown_docs()
        if p.is_relative_to(ROOT / "docs") and p.name != "README.md"
    }
    assert pages - linked == set()


# --- the checkers themselves ----------------------------------------------------------------


def test_checker_reports_outside_references():
    text = "see ../" + "shared/spec/SIM_" + "PROTOCOL.md\nfine line\n"
    found = outside_references(text)
    assert (1, "../" + "shared") in found and (1, "SIM_" + "PROTOCOL.md") in found
    assert all(number == 1 for number, _ in found)
    assert outside_references("docs/protocols/simulator.md and docs/architecture.md") == []


def test_checker_reports_broken_and_outside_links(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("# Title\n\n## The `SET` command (wind)\n")
    page = tmp_path / "docs" / "a.md"
    page.write_text(
        "# A\n"
        "[ok](b.md) [anchor](b.md#the-set-command-wind) [self](#a) [web](https://example.org)\n"
        "[gone](c.md) [bad anchor](b.md#nope) [out](../../elsewhere.md) [abs](/etc/passwd)\n"
        "`[in code](c.md)`\n"
        "```\n[in a fence](c.md)\n```\n"
        "[file](file:///etc/passwd)\n"
    )
    problems = broken_links(page, root=tmp_path)
    assert len(problems) == 5, problems
    assert any("c.md: no such file" in p for p in problems)
    assert any("#nope" in p for p in problems)
    assert any("elsewhere.md: points outside" in p for p in problems)
    assert any("/etc/passwd: absolute path" in p for p in problems)
    assert any("file:///etc/passwd: links outside" in p for p in problems)


def test_slugs_follow_github():
    seen: dict[str, int] = {}
    assert slug("GETGEO and GETCONF", seen) == "getgeo-and-getconf"
    assert slug("Messages (simulator to client)", seen) == "messages-simulator-to-client"
    e1 = "E1: height from the pad (paper Fig. 6)"
    assert slug(e1, seen) == "e1-height-from-the-pad-paper-fig-6"
    assert slug("RESULT codes", seen) == "result-codes"
    assert slug("RESULT codes", seen) == "result-codes-1"


def test_checker_finds_the_imports_of_python_blocks():
    text = ("from skeye.a import b  # not in code\n"
            "```python\n"
            "import skeye.gym  # registers\n"
            "from skeye.vision.detector import detect, PadEstimate as Est\n"
            "import cv2\n"
            "```\n"
            "```sh\n"
            "from skeye.c import d\n"
            "```\n"
            "~~~py\n"
            "from skeye.e import (f, g)\n"
            "~~~\n")
    assert python_imports(text) == [
        (3, "skeye.gym", ()),
        (4, "skeye.vision.detector", ("detect", "PadEstimate")),
        (11, "skeye.e", ("f", "g")),
    ]


def test_checker_reports_what_does_not_resolve():
    problems = unresolved_imports([
        ("a.md:1", "skeye.vision.calibration", ("load_calibration", "detect")),
        ("a.md:2", "skeye.no_such_module", ()),
        ("a.md:3", "skeye.vision", ("detector",)),
    ])
    assert problems == ["a.md:1: skeye.vision.calibration has no detect",
                        "a.md:2: cannot import skeye.no_such_module: No module named "
                        "'skeye.no_such_module'"]


_REPO_PATH = re.compile(
    r"`((?:skeye|tests|benchmarks|examples|tools|docs)/[\w./-]*(?:\.\w+|/))(?:::\w+|:\d+)?`")
NOT_OURS = {"examples/motor_on_off.c"}  # the AscTec AutoPilot SDK's example, compatibility.md
"""Paths in the pages that name another project's files."""


def repository_paths(text: str) -> list[tuple[int, str]]:
    """(line number, path) of every file or folder of the repository the text names in inline
    code (`` `skeye/pilot/cli.py` ``, `` `tests/x.py::test_y` ``, `` `docs/img/` ``): a name
    with an extension, or ending in ``/``, under one of the repository's top folders."""
    found: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        found.extend((number, path) for path in _REPO_PATH.findall(line)
                     if path not in NOT_OURS)
    return found


def test_files_the_pages_name_exist():
    problems: list[str] = []
    checked = 0
    for path in markdown_docs():
        for number, named in repository_paths(path.read_text(encoding="utf-8")):
            checked += 1
            if not (ROOT / named).exists():
                problems.append(f"{path.relative_to(ROOT)}:{number}: {named}: no such file")
    assert checked > 100, "the pages name hardly any file: the pattern is wrong"
    assert not problems, "the pages name files the repository lacks:\n" + "\n".join(problems)


def test_checker_finds_the_files_a_page_names():
    text = ("see `skeye/pilot/cli.py` and `tests/a.py::test_b`, `docs/img/`\n"
            "not `skeye/Hover-v0`, `skeye.gym`, `x/skeye/y.py`, nor `examples/motor_on_off.c`\n"
            "`benchmarks/bench_sim.py:12` `skeye pilot --help`\n")
    assert repository_paths(text) == [(1, "skeye/pilot/cli.py"), (1, "tests/a.py"),
                                      (1, "docs/img/"), (3, "benchmarks/bench_sim.py")]


_DOTTED = re.compile(r"`(skeye(?:\.\w+)+)(?:\(\))?`")

_RESOLVE_DOTTED = """
import importlib, json, sys
problems = []
for where, name in json.loads(sys.stdin.read()):
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
            break
        except ImportError:
            continue
    for i, attr in enumerate(parts[cut:], start=cut):
        if not hasattr(obj, attr):
            problems.append(f"{where}: {name}: {'.'.join(parts[:i])} has no {attr}")
            break
        obj = getattr(obj, attr)
print(json.dumps(problems))
"""


def dotted_names(text: str) -> list[tuple[int, str]]:
    """(line number, name) of every ``skeye.a.b`` (or ``skeye.a.f()``) in inline code."""
    return [(number, name) for number, line in enumerate(text.splitlines(), start=1)
            for name in _DOTTED.findall(line)]


def unresolved_names(names: list[tuple[str, str]], root: Path = ROOT) -> list[str]:
    """What is wrong with (where, dotted name) pairs: each must be a module or an attribute of
    one; resolved in a child process, as the imports are."""
    done = subprocess.run([sys.executable, "-c", _RESOLVE_DOTTED], input=json.dumps(names),
                          capture_output=True, text=True, cwd=root, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_names_the_pages_give_exist():
    names = [(f"{path.relative_to(ROOT)}:{number}", name)
             for path in markdown_docs()
             for number, name in dotted_names(path.read_text(encoding="utf-8"))]
    assert len(names) > 50, "the pages name hardly any module: the pattern is wrong"
    problems = unresolved_names(names)
    assert not problems, "names in the pages that skeye does not have:\n" + "\n".join(problems)


def test_checker_resolves_dotted_names():
    assert dotted_names("`skeye.gym` and `skeye.pixels.frame_image()`, not skeye.x or `a.b`") \
        == [(1, "skeye.gym"), (1, "skeye.pixels.frame_image")]
    assert unresolved_names([("a.md:1", "skeye.wire.sim_lines.LineDecoder"),
                             ("a.md:2", "skeye.link.Nothing"),
                             ("a.md:3", "skeye.vision.detector.detect.nope")]) == [
        "a.md:2: skeye.link.Nothing: skeye.link has no Nothing",
        "a.md:3: skeye.vision.detector.detect.nope: skeye.vision.detector.detect has no nope"]


# --- documented defaults against the code -------------------------------------------------

_PARAM_VALUE = re.compile(r"`(\w+)`\s+(-?\d+(?:\.\d+)?(?:e-?\d+)?)")


def sensor_parameter_table(text: str) -> dict[str, dict[str, float]]:
    """Type -> {key: default} of the table under the "Sensor parameters" heading (its rows
    after the header): each parameter is written `` `Key` value unit``; a row of ``-`` has
    none."""
    table: dict[str, dict[str, float]] = {}
    in_section = in_body = False
    for line in text.splitlines():
        heading = _HEADING.match(line)
        if heading:
            in_section = heading.group(2).strip().lower() == "sensor parameters"
            in_body = False
            continue
        if in_section and line.startswith("| ---"):
            in_body = True
            continue
        if not in_body or not line.startswith("| `"):
            continue
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        table[cells[0].strip("`")] = {key: float(value)
                                      for key, value in _PARAM_VALUE.findall(cells[1])}
    return table


def test_sensor_parameter_defaults_are_the_codes():
    from skeye.sim.sensors import SENSOR_CLASSES

    page = (ROOT / "docs" / "protocols" / "simulator.md").read_text(encoding="utf-8")
    table = sensor_parameter_table(page)
    code = {cls.type_name: {p.key: float(p.default) for p in cls.PARAMS}
            for cls in SENSOR_CLASSES.values()}
    problems = [f"{kind}: the code has no such sensor type" for kind in table.keys() - code]
    problems += [f"{kind}: not in the table" for kind in code.keys() - table.keys()]
    for kind in code.keys() & table.keys():
        documented, actual = table[kind], code[kind]
        problems += [f"{kind}: {key} is not documented (default {actual[key]:g})"
                     for key in actual.keys() - documented.keys()]
        problems += [f"{kind}: {key} is no parameter of the code"
                     for key in documented.keys() - actual.keys()]
        problems += [f"{kind}: {key} documented {documented[key]:g}, the code's {actual[key]:g}"
                     for key in documented.keys() & actual.keys()
                     if documented[key] != actual[key]]
    assert not problems, ("docs/protocols/simulator.md, Sensor parameters:\n"
                          + "\n".join(sorted(problems)))


def test_checker_reads_the_sensor_parameter_table():
    text = ("## Other\n| `Sonar` | `MaxRange` 1 m |\n"
            "#### Sensor parameters\n\n| `Type` | parameters (default) |\n| --- | --- |\n"
            "| `GroundTruth` | - |\n"
            "| `Barometer` | `NoiseSigma` 1.5 Pa, `RotorThrustCoefficient` 0 N s^2 (the file: "
            "8.5e-6), `Tiny` 1e-6 |\n\nAfter the table `Sonar` 3.\n## Next\n| `Gyro` | `A` 2 |\n")
    assert sensor_parameter_table(text) == {
        "GroundTruth": {},
        "Barometer": {"NoiseSigma": 1.5, "RotorThrustCoefficient": 0.0, "Tiny": 1e-6},
    }


def test_the_control_reference_gives_every_keyword_of_connect_and_spawn():
    """docs/control.md writes out ``skeye.connect(...)`` and ``spawn(...)``: every keyword they
    take is there (``sync_clock``, which several clients each flying a robot in lockstep need,
    was missing from the API reference and said only on the protocol page)."""
    import inspect

    from skeye.control.connection import Connection

    text = (ROOT / "docs" / "control.md").read_text(encoding="utf-8")
    for written, function in (("skeye.connect(", Connection.__init__),
                              ("spawn(", Connection.spawn)):
        start = text.index(f"`{written}") + 1
        signature = text[start:text.index("`", start)]
        documented = set(re.findall(r"(\w+)=", signature))
        taken = {p.name for p in inspect.signature(function).parameters.values()
                 if p.default is not inspect.Parameter.empty}
        assert taken <= documented, (written, sorted(taken - documented))
