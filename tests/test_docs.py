"""The user guide: it builds without a warning, and every code block runs as written.

``docs/`` is built with ``sphinx-build -W --keep-going`` (a broken reference, a docstring that
is not valid reStructuredText or a module that no longer imports fails), and every script in
``docs/examples/`` runs in a temporary directory, with checks on what it prints. The example
plugin package is installed with pip into a temporary target, as a user would install it.
Sphinx and myst-parser missing: a failure under CI=true, a skip elsewhere.

Every page's code blocks are extracted and run in order, as a reader following the page
would, in one temporary folder per page that holds a copy of ``docs/examples/data`` (pages
name files from the repository's root): each ``python`` block as a script of its own (files
persist from block to block, variables do not); each ``pygran`` line of a ``bash`` block, and
each ``text`` block that starts with ``$ pygran ...``, as a command. A ``text`` block right
after a block (or after a literal include of an example script) is what it prints: each of its
lines must appear, in order, in the printed lines; ``...`` alone skips lines, inside a line it
stands for any text; numbers must read exactly as shown, unless a comment line
``% numbers within N %`` before the block allows a relative tolerance. The other lines of
``bash`` blocks set up an environment (``pip install``, ``apt-get``, ``bash
scripts/bootstrap.sh``, ``sphinx-build``: the CI job and :func:`test_docs_build_without_warnings`
run them) or start servers (``dask scheduler``); they are checked, not run: the paths they
name exist, and every ``mpirun`` carries the flags it needs as root and with more ranks than
cores. Blocks that need LIGGGHTS or ``mpirun`` follow ``require_solver``: a failure under
``CI=true``, a skip elsewhere.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

from pygran_core import registry
from pygran_core.testing.solvers import in_ci, require_solver

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
EXAMPLES = DOCS / "examples"
#: Every script of docs/examples and the test that runs it; a new example needs a test here.
TESTED_SCRIPTS = {
    "first_simulation.py",
    "analyse_liggghts.py",
    "use_example_plugin.py",
    "nsim_liggghts.py",
    "coarse_grain_hopper.py",  # these two run in tests/test_coarse_grain.py
    "coarse_grain_bed.py",
}


def _require(*modules: str) -> None:
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        message = f"{', '.join(missing)} not installed: pip install sphinx myst-parser"
        if in_ci():
            pytest.fail(f"CI=true and the documentation tools are missing: {message}", pytrace=False)
        pytest.skip(message)


def _run(args: list[str], cwd: Path, timeout: float = 120, **env: str) -> str:
    """Run ``args`` in ``cwd``; return stdout, or fail with both streams."""
    environment = {**os.environ, "OMP_NUM_THREADS": "1", **env}  # 1 thread: steady on a busy CI machine
    done = subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=environment)
    if done.returncode != 0:
        streams = f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
        pytest.fail(f"{' '.join(args)} exited {done.returncode}\n{streams}")
    return done.stdout


@dataclass(frozen=True)
class Block:
    """A fenced block of a page: its info string (``python``, ``text``, ``{literalinclude}
    examples/x.py``), first line number, text, and the tolerance its comment allows."""

    info: str
    line: int
    text: str
    tolerance: float | None = None
    #: whether only blank and comment lines separate it from the block before it
    follows: bool = False


FENCE = re.compile(r"^(```+|~~~+)(.*)$")
TOLERANCE = re.compile(r"^%\s*numbers within ([0-9.]+)\s*%")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
#: Pages whose blocks the runner executes: the guide, not its example scripts or build.
PAGES = sorted(
    p.relative_to(DOCS).as_posix()
    for p in DOCS.rglob("*.md")
    if not {"examples", "_build"} & set(p.relative_to(DOCS).parts)
)
#: Set-up commands: checked (the paths they name exist), run by CI and the build test.
SETUP = ("pip ", "python -m venv", "source ", "apt-get ", "bash scripts/", "sphinx-build ", "sudo ")
SERVERS = ("dask scheduler", "dask worker")


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of ``page``, in order."""
    found: list[Block] = []
    lines = page.read_text().splitlines()
    k, previous_end = 0, -2
    while k < len(lines):
        opening = FENCE.match(lines[k])
        if not opening:
            k += 1
            continue
        fence, info = opening.group(1), opening.group(2).strip()
        end = next(
            j
            for j in range(k + 1, len(lines))
            if lines[j].startswith(fence) and not lines[j][len(fence) :].strip()
        )
        before = next((lines[j] for j in range(k - 1, -1, -1) if lines[j].strip()), "")
        allowed = TOLERANCE.match(before)
        between = lines[previous_end + 1 : k] if previous_end >= 0 else ["not a block"]
        follows = all(not line.strip() or line.startswith("%") for line in between)
        tolerance = float(allowed[1]) / 100 if allowed else None
        found.append(Block(info, k + 1, "\n".join(lines[k + 1 : end]), tolerance, follows))
        k, previous_end = end + 1, end
    return found


def expected_output(page: str, script: str) -> Block:
    """The ``text`` block that comes next after the literal include of ``examples/<script>``
    on ``page``, prose between them allowed (without its ``$ command`` line)."""
    found = blocks(DOCS / page)
    for block, after in zip(found, found[1:]):
        if block.info == f"{{literalinclude}} examples/{script}" and after.info == "text":
            shown = after.text.partition("\n")[2] if after.text.startswith("$ ") else after.text
            return Block("text", after.line, shown, after.tolerance, True)
    raise AssertionError(f"{page} shows no output after its include of examples/{script}")


def _line_pattern(line: str) -> tuple[re.Pattern[str], list[str]]:
    """A regex matching ``line`` with its numbers as groups (and ``...`` as any text), and
    the numbers as written."""
    parts, numbers, last = [], [], 0
    for match in NUMBER.finditer(line):
        parts.append(re.escape(line[last : match.start()]).replace(re.escape("..."), ".*"))
        parts.append(f"({NUMBER.pattern})")
        numbers.append(match.group())
        last = match.end()
    parts.append(re.escape(line[last:]).replace(re.escape("..."), ".*"))
    return re.compile("".join(parts).strip() + "$"), numbers


def _same_numbers(got: tuple[str, ...], want: list[str], tolerance: float | None) -> bool:
    if tolerance is None:
        return list(got) == want
    return all(abs(float(g) - float(w)) <= tolerance * abs(float(w)) for g, w in zip(got, want))


def check_printed(printed: str, expected: Block, where: str) -> None:
    """Every line of ``expected`` in ``printed``, in order (see the module docstring)."""
    got = [line.strip() for line in printed.splitlines()]
    position = 0
    for want in expected.text.splitlines():
        want = want.strip()
        if want in ("", "..."):
            continue
        pattern, numbers = _line_pattern(want)
        for k in range(position, len(got)):
            match = pattern.match(got[k])
            if match and _same_numbers(match.groups(), numbers, expected.tolerance):
                position = k + 1
                break
        else:
            allowed = (
                "" if expected.tolerance is None else f" (numbers within {100 * expected.tolerance:g} %)"
            )
            pytest.fail(
                f"{where}: the guide shows {want!r}{allowed}, which is not among the lines printed after "
                f"line {position}:\n{printed}",
                pytrace=False,
            )


def _needs(code: str) -> None:
    """A block that needs LIGGGHTS or mpirun: fail under CI=true without them, else skip."""
    if "liggghts" in code.lower():
        engines = registry.available("engine")
        if "liggghts" not in engines:
            if in_ci():
                pytest.fail("CI=true and the liggghts engine is not installed", pytrace=False)
            pytest.skip("the liggghts engine is not installed: pip install ./plugins/pygran-liggghts")
        require_solver(engines["liggghts"].spec.locate_solver)


def _check_setup(command: str, where: str) -> None:
    """A set-up or server command shown, not run: the paths it names exist; ``mpirun``
    carries ``--allow-run-as-root`` and ``--oversubscribe``."""
    words = shlex.split(command)
    if words[0] == "mpirun":
        for flag in ("--allow-run-as-root", "--oversubscribe"):
            assert flag in words, (
                f"{where}: {command!r} lacks {flag}, which mpirun needs as root or on few cores"
            )
    named = words[-2:-1] if words[0] == "sphinx-build" else words  # its source, not what it builds
    for word in named:
        if word.startswith(("./", "scripts/", "docs")) or word.endswith((".sh", ".toml")):
            assert (ROOT / word).exists(), f"{where}: {command!r} names {word}, which does not exist"


def run_page(page: str, workspace: Path) -> int:
    """Run the code blocks of ``page`` (see the module docstring); returns how many ran."""
    found = blocks(DOCS / page)
    ran = 0
    for index, block in enumerate(found):
        after = found[index + 1] if index + 1 < len(found) else None
        shows = (
            after is not None and after.info == "text" and after.follows and not after.text.startswith("$")
        )
        expected = after if shows else None
        where = f"docs/{page}:{block.line}"
        printed = None
        if block.info == "python":
            _needs(block.text)
            script = workspace / f"block{block.line}.py"
            script.write_text(block.text + "\n")
            printed = _run([sys.executable, script.name], workspace, timeout=300)
        elif block.info == "text" and block.text.startswith("$ pygran "):
            command, _, shown = block.text.partition("\n")
            printed = _pygran(command[2:], workspace)
            check_printed(printed, Block("text", block.line, shown, block.tolerance), where)
            ran += 1
            continue
        elif block.info in ("bash", "sh", "console"):
            outputs, folder = [], workspace
            for line in block.text.splitlines():
                command = line.split(" #", 1)[0].strip()
                if not command:
                    continue
                if command.startswith("cd "):
                    folder = folder / shlex.split(command)[1]
                    assert folder.is_dir(), f"{where}: {command!r}: no such folder"
                elif command.startswith("pygran "):
                    outputs.append(_pygran(command, folder))
                elif command.startswith(SETUP + SERVERS) or command.startswith("mpirun "):
                    _check_setup(command, where)
                    continue
                else:
                    pytest.fail(f"{where}: the runner does not know how to run {command!r}", pytrace=False)
            printed = "\n".join(outputs) if outputs else None
        if printed is None:
            continue
        ran += 1
        if expected is not None:
            check_printed(printed, expected, where)
    return ran


def _pygran(command: str, workspace: Path) -> str:
    """Run a ``pygran ...`` command line as the shell would (quotes removed, no globbing)."""
    return _run([sys.executable, "-m", "pygran_core.cli", *shlex.split(command)[1:]], workspace)


@pytest.fixture
def workspace(tmp_path: Path) -> Path:
    """A folder as the guide's reader has it: ``docs/examples/data`` beside them."""
    shutil.copytree(EXAMPLES / "data", tmp_path / "docs" / "examples" / "data")
    return tmp_path


@pytest.mark.parametrize("page", PAGES)
def test_the_guide_runs_as_written(page: str, workspace: Path) -> None:
    run_page(page, workspace)


def test_the_runner_checks_what_it_should(tmp_path: Path) -> None:
    shown = Block("text", 1, "step 20000: 571 particles\n...\nrate 20.2 per ... steps")
    check_printed("header\nstep 20000: 571 particles\nnoise\nrate 20.2 per 1000 steps\n", shown, "ok")
    with pytest.raises(pytest.fail.Exception, match="rate 20.2"):
        check_printed("step 20000: 571 particles\nrate 20.3 per 1000 steps\n", shown, "off")
    loose = Block("text", 1, "rate 20.2 per 1000 steps", tolerance=0.01)
    check_printed("rate 20.3 per 1000 steps", loose, "within 1 %")
    with pytest.raises(AssertionError, match="--allow-run-as-root"):
        _check_setup("mpirun -np 4 python script.py", "plain")
    page = tmp_path / "page.md"
    page.write_text("% numbers within 2 %\n```text\nx 1\n```\n")
    assert blocks(page) == [Block("text", 2, "x 1", 0.02)]
    page.write_text("```python\nprint(1)\n```\n\n```text\n1\n```\nprose\n```text\n2\n```\n")
    assert [b.follows for b in blocks(page)] == [False, True, False]


def test_every_example_is_tested() -> None:
    assert {p.name for p in EXAMPLES.glob("*.py")} == TESTED_SCRIPTS


def test_docs_build_without_warnings(tmp_path: Path) -> None:
    _require("sphinx", "myst_parser")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-q",
            "-b",
            "html",
            "-d",
            str(tmp_path / "doctrees"),
            str(DOCS),
            str(tmp_path / "html"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, f"sphinx-build failed:\n{out.stdout}\n{out.stderr}"
    pages = {p.stem for p in (tmp_path / "html").glob("*.html")}
    guide = {"index", "installation", "first-simulation", "analysis", "parallel", "plugins", "command-line"}
    assert guide <= pages
    api = (tmp_path / "html" / "api" / "simulation.html").read_text()
    assert 'id="pygran_core.simulation.dem.DEM.insert"' in api  # autodoc really ran


def test_first_simulation(tmp_path: Path) -> None:
    printed = _run([sys.executable, str(EXAMPLES / "first_simulation.py")], tmp_path)
    check_printed(
        printed, expected_output("first-simulation.md", "first_simulation.py"), "first_simulation.py"
    )
    assert "100 particles at t = 0.151 s" in printed
    assert "11 frames; mean coordination number" in printed
    assert {p.name for p in (tmp_path / "out").iterdir()} >= {"traj.h5", "energy.txt", "pygran.log"}
    coordination = float(printed.rsplit("mean coordination number", 1)[1])
    assert 3 < coordination < 6  # a settled bed, not beads in the air


def test_analyse_liggghts(tmp_path: Path) -> None:
    printed = _run([sys.executable, str(EXAMPLES / "analyse_liggghts.py")], tmp_path)
    check_printed(printed, expected_output("analysis.md", "analyse_liggghts.py"), "analyse_liggghts.py")
    assert "frame 2: step 30000, 423 particles, 320 wall cells" in printed
    assert "160 particles below z = 1 mm" in printed
    assert "around step 22500: 20.2 particles per 1000 steps" in printed
    assert "wrote 160 particles to low.h5" in printed
    dumps = str(EXAMPLES / "data" / "liggghts-hopper" / "particles*.dump")
    info = _run([sys.executable, "-m", "pygran_core.cli", "info", dumps], tmp_path)
    assert "timesteps:  20000 to 30000" in info


def test_example_plugin(tmp_path: Path) -> None:
    site, source = tmp_path / "site", tmp_path / "pygran-example"
    shutil.copytree(EXAMPLES / "pygran-example", source)  # the build leaves nothing in docs/
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(site),
            str(source),
        ],
        tmp_path,
    )
    env = {
        "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
        "PYGRAN_STRICT_PLUGINS": "1",
    }
    printed = _run([sys.executable, str(EXAMPLES / "use_example_plugin.py")], tmp_path, **env)
    check_printed(printed, expected_output("plugins.md", "use_example_plugin.py"), "use_example_plugin.py")
    assert "'ballistic'" in printed and "'StiffSpringDashpot'" in printed and "'xyz'" in printed
    assert "restitution 0.900" in printed
    assert "2 frames; last frame z = [1. 1.]" in printed
    plugins = _run([sys.executable, "-m", "pygran_core.cli", "plugins"], tmp_path, **env)
    assert all(name in plugins for name in ("example-engine", "example-model", "example-reader"))


def test_nsim_liggghts(tmp_path: Path) -> None:
    engines = registry.available("engine")
    if "liggghts" not in engines or "mpi" not in engines["liggghts"].spec.capabilities:
        if in_ci():
            pytest.fail("CI=true and the liggghts engine (with capability 'mpi') is not installed")
        pytest.skip("the liggghts engine is not installed: pip install ./plugins/pygran-liggghts")
    require_solver(engines["liggghts"].spec.locate_solver)
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        if in_ci():
            pytest.fail("CI=true and mpirun is missing: apt-get install -y openmpi-bin")
        pytest.skip("mpirun is missing: apt-get install -y openmpi-bin")
    shown = next(b for b in blocks(DOCS / "parallel.md") if b.text.startswith("$ mpirun"))
    command = shlex.split(shown.text.partition("\n")[0][2:])  # the guide's own command line
    assert command[-1] == "docs/examples/nsim_liggghts.py"
    python = command.index("python")
    printed = _run(
        [mpirun, *command[1:python], sys.executable, str(EXAMPLES / "nsim_liggghts.py")],
        tmp_path,
        timeout=300,
    )
    # each group prints its own line when it is done: in either order
    shown = expected_output("parallel.md", "nsim_liggghts.py")
    shown = replace(shown, text="\n".join(sorted(shown.text.splitlines())))
    check_printed("\n".join(sorted(printed.splitlines())), shown, "nsim_liggghts.py")
    assert "run0: e = 0.3, 100 particles" in printed
    assert "run1: e = 0.9, 100 particles" in printed
    for run in ("run0", "run1"):
        assert (tmp_path / "out-nsim" / run / "traj.dump").is_file()
