"""Parameter studies: many independent simulations, each in its own process and folder, run as
Dask tasks (or one after the other here), with a table of inputs and results, retries of failed
runs and resume of an interrupted study.

::

    def settle(output, restitution):               # one run: its folder, then its parameters
        with simulation.DEM(output=output, ...) as sim:
            ...
        return {"height": h}                      # its results: named numbers or strings

    runs = Study(settle, parameters=grid(restitution=[0.3, 0.6, 0.9]), output="study").run()

Run ``i`` writes to ``<output>/run<i>`` (its log in ``study.log`` there) and executes in a new
Python process started for it, so a solver that crashes or exits ends that run only. A run is
a function ``f(output, **parameters)`` returning a mapping of results (or None), or the path
of a script, which reads its run with :func:`current` and records results with
:meth:`CurrentRun.report`. LIGGGHTS runs take their own MPI ranks from the engine's
``nprocs``; size the cluster so that workers times ranks fits the cores.

``<output>/study.json`` is the journal, rewritten atomically after every run; the table
``<output>/results.csv`` (one row per run: ``run``, the parameters, ``status``, ``attempts``,
``seconds``, the results, ``error``) likewise. ``resume=True`` continues a study from its
journal: finished runs are skipped and the others run again; rows added to the table since
run too, and a recorded run whose parameters changed is a :class:`ConfigError`.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import os
import signal
import subprocess
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pygran_core import cluster
from pygran_core.errors import ConfigError, PyGranWarning, UnsupportedFeature

PathLike = str | os.PathLike[str]
#: The environment variable that tells a script which run it is (its folder).
RUN_VARIABLE = "PYGRAN_STUDY_RUN"
JOURNAL, TABLE, LOG, LOCK = "study.json", "results.csv", "study.log", "study.lock"
#: Columns of the table besides the parameters and the results.
RESERVED = ("run", "status", "attempts", "seconds", "error")
_PARAMETERS, _RESULTS, _FAILURE, _FUNCTION = "parameters.json", "results.json", "error.txt", "function.pkl"


# -- the parameter table -------------------------------------------------------------------


def grid(**axes: Sequence[Any]) -> list[dict[str, Any]]:
    """Every combination of the values of ``axes``, the last varying fastest:
    ``grid(e=[0.3, 0.9], mu=[0.1, 0.5])`` is four rows."""
    for name, values in axes.items():
        if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
            raise ConfigError(f"grid: {name}= needs a non-empty list of values, not {values!r}")
    return [dict(zip(axes, combination, strict=True)) for combination in itertools.product(*axes.values())]


def rows_of(parameters: Any) -> list[dict[str, Any]]:
    """The study's rows from ``parameters``: a list of mappings (a pandas DataFrame's
    ``to_dict("records")``) or a mapping of equal-length columns; every value must be
    representable in JSON."""
    if isinstance(parameters, Mapping):
        lengths = {
            k: len(v) for k, v in parameters.items() if isinstance(v, Sequence) and not isinstance(v, str)
        }
        if len(lengths) != len(parameters) or len(set(lengths.values())) != 1:
            raise ConfigError(
                f"parameters: a mapping must give every parameter a list of one length (one value per run), "
                f"got {parameters!r}; or give a list of rows, or grid(...) for every combination"
            )
        parameters = [
            dict(zip(parameters, row, strict=True)) for row in zip(*parameters.values(), strict=True)
        ]
    if isinstance(parameters, (str, bytes)) or not isinstance(parameters, Sequence) or not parameters:
        raise ConfigError(f"parameters: give a non-empty list of rows (mappings), not {parameters!r}")
    rows = []
    for index, row in enumerate(parameters):
        if not isinstance(row, Mapping):
            raise ConfigError(
                f"parameters: row {index} is {row!r}, not a mapping of parameter names to values"
            )
        clash = [k for k in row if k in RESERVED or k == "output" or not isinstance(k, str)]
        if clash:
            raise ConfigError(f"parameters: row {index} uses the reserved names {clash}; rename them")
        try:
            rows.append(json.loads(json.dumps(dict(row), default=_plain)))
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"parameters: row {index} has a value JSON cannot hold ({exc})") from None
    return rows


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as Python numbers and lists (for JSON)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} {value!r}")


# -- one run, in its own process -----------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    """What one attempt of a run gave: ``results`` when it succeeded, else ``error``."""

    index: int
    ok: bool
    seconds: float
    results: dict[str, Any] = field(default_factory=dict)
    error: str = ""


@dataclass(frozen=True)
class CurrentRun:
    """The run a script executes as, inside a study (see :func:`current`)."""

    index: int
    output: Path
    parameters: dict[str, Any]

    def report(self, **results: Any) -> None:
        """Record this run's results (numbers, strings, booleans): columns of the study's table."""
        _write_json(self.output / _RESULTS, _checked_results(results, self.parameters))


def current() -> CurrentRun:
    """Inside a study's script: this run's index, folder (``output``) and ``parameters``."""
    folder = os.environ.get(RUN_VARIABLE)
    if not folder:
        raise ConfigError(
            f"study.current(): this script is not running inside a Study ({RUN_VARIABLE} is not set); "
            "run it with Study('script.py', parameters=...).run()"
        )
    path = Path(folder)
    return CurrentRun(int(path.name.removeprefix("run")), path, json.loads((path / _PARAMETERS).read_text()))


def _checked_results(results: Any, parameters: Mapping[str, Any]) -> dict[str, Any]:
    if results is None:
        return {}
    if not isinstance(results, Mapping):
        raise ConfigError(f"a run returned {results!r}; return a mapping of result names to values, or None")
    for name, value in results.items():
        if not isinstance(name, str) or name in RESERVED or name in parameters:
            raise ConfigError(f"result {name!r} has the name of a parameter or of a column of the table")
        if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
            value = value.item()
        if not isinstance(value, (int, float, str, bool)) and value is not None:
            raise ConfigError(
                f"result {name!r} is {type(value).__name__}; results are numbers, strings or booleans"
            )
    return {name: value.item() if hasattr(value, "item") else value for name, value in results.items()}


def _write_json(path: Path, value: Any) -> None:
    _write_atomically(path, json.dumps(value, indent=1, default=_plain))


def _write_atomically(path: Path, text: str) -> None:
    partial = path.with_name(path.name + ".partial")
    partial.write_text(text)
    os.replace(partial, path)


def child() -> None:
    """The body of a function run's process: call the function pickled in the run's folder
    (:data:`RUN_VARIABLE`) on the run's parameters and write its results, or the error (then
    exit with status 1)."""
    import cloudpickle

    path = Path(os.environ[RUN_VARIABLE])
    try:
        function = cloudpickle.loads((path / _FUNCTION).read_bytes())
        parameters = json.loads((path / _PARAMETERS).read_text())
        _write_json(path / _RESULTS, _checked_results(function(path, **parameters), parameters))
    except BaseException as exc:  # noqa: BLE001 - every failure of the user's run is reported
        (path / _FAILURE).write_text(f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}")
        traceback.print_exc()  # into the run's log
        sys.exit(1)


#: Starts a run's program (argv[2:]) so that it ends with the process that started it
#: (argv[1]): a worker shut down, or a study interrupted, leaves no run behind.
_LAUNCHER = (
    "import ctypes, os, signal, sys\n"
    "ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG, kept across exec\n"
    "if os.getppid() != int(sys.argv[1]): sys.exit('the study ended before this run started')\n"
    "os.execv(sys.argv[2], sys.argv[2:])"
)


def execute(
    index: int,
    folder: str,
    parameters: dict[str, Any],
    command: Sequence[str],
    function: bytes | None,
    timeout: float | None,
) -> Outcome:
    """One attempt of run ``index`` on ``parameters`` in ``folder`` (a Dask task, or called
    here): start its process, wait for it, and read what it left."""
    path = Path(folder)
    start = time.monotonic()
    try:
        process = _start(index, path, parameters, command, function)
    except OSError as exc:  # a folder that cannot be written, a full disk
        return Outcome(index, False, time.monotonic() - start, error=f"could not start in {path}: {exc}")
    try:
        code = process.wait(timeout)
    except subprocess.TimeoutExpired:
        _end(process)
        return Outcome(index, False, time.monotonic() - start, error=f"timed out after {timeout:g} s")
    except BaseException:  # an interrupted study ends its runs
        _end(process)
        raise
    seconds = time.monotonic() - start
    if (path / _FAILURE).is_file():
        return Outcome(index, False, seconds, error=(path / _FAILURE).read_text().split("\n\n")[0])
    if code != 0:
        cause = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exited with status {code}"
        lines = (path / LOG).read_text(errors="replace").strip().splitlines()
        last = f" after printing {lines[-1].strip()!r}" if lines and not lines[-1].startswith("---") else ""
        return Outcome(index, False, seconds, error=f"its process {cause}{last}; see {path / LOG}")
    results = json.loads((path / _RESULTS).read_text()) if (path / _RESULTS).is_file() else {}
    return Outcome(index, True, seconds, results)


def _start(
    index: int, path: Path, parameters: dict[str, Any], command: Sequence[str], function: bytes | None
) -> subprocess.Popen[bytes]:
    """Lay out the run's folder and start its process, its output appended to its log."""
    path.mkdir(parents=True, exist_ok=True)
    for stale in (_RESULTS, _FAILURE):
        (path / stale).unlink(missing_ok=True)
    _write_json(path / _PARAMETERS, parameters)
    if function is not None:
        (path / _FUNCTION).write_bytes(function)
    launch = [sys.executable, "-c", _LAUNCHER, str(os.getpid())] if sys.platform.startswith("linux") else []
    with open(path / LOG, "ab") as log:
        log.write(f"--- study run {index}, started {time.strftime('%Y-%m-%d %H:%M:%S')}\n".encode())
        log.flush()
        return subprocess.Popen(
            [*launch, *command],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, RUN_VARIABLE: str(path)},
            start_new_session=True,  # its own process group: ending it ends the MPI ranks it started
        )


@contextlib.contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    """Hold the lock file ``path`` (released when its process ends, however it ends)."""
    import fcntl

    with open(path, "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(
                f"Study: another study is running in {path.parent} (it holds {path.name}); wait for it "
                "to end, or choose another output folder"
            ) from None
        yield


def _end(process: subprocess.Popen[bytes]) -> None:
    with contextlib.suppress(ProcessLookupError):  # it may have ended meanwhile
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


# -- the study -----------------------------------------------------------------------------


class Study:
    """A parameter study: ``run`` (a function ``f(output, **parameters)`` or a script's path)
    once per row of ``parameters``, each in ``<output>/run<i>``.

    ``client``: a ``dask.distributed.Client``, a scheduler address, None for a
    ``LocalCluster`` of ``workers`` processes (default: one per core), or ``"serial"`` for one
    run after the other from here (no Dask needed for a script). A failed run is tried
    ``retries`` more times; ``timeout`` (s) ends a run that takes longer. ``progress``: the
    progress line on standard error (default: on a terminal). See the module docstring.
    """

    def __init__(
        self,
        run: Callable[..., Any] | PathLike,
        parameters: Any,
        output: PathLike = "study",
        *,
        client: Any = None,
        workers: int | None = None,
        retries: int = 1,
        timeout: float | None = None,
        resume: bool = False,
        progress: bool | None = None,
    ) -> None:
        self.rows = rows_of(parameters)
        self.output = Path(output).absolute()
        self.client, self.workers, self.progress = client, workers, progress
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise ConfigError(
                f"retries={retries!r}: give how many more times a failed run is tried (0 or more)"
            )
        if timeout is not None and not (isinstance(timeout, (int, float)) and timeout > 0):
            raise ConfigError(f"timeout={timeout!r}: give a run's longest duration in seconds, or None")
        self.retries, self.timeout = retries, timeout
        cluster.check(client, workers, "Study")
        self._command, self._function = self._program(run)
        self.journal = self._open_journal(resume)

    def _program(self, run: Callable[..., Any] | PathLike) -> tuple[list[str], bytes | None]:
        """The command that starts a run's process, and the pickled function it calls."""
        if isinstance(run, (str, os.PathLike)):
            script = Path(run).absolute()
            if script.suffix != ".py" or not script.is_file():
                raise ConfigError(
                    f"Study: {os.fspath(run)!r} is not a Python script (a .py file that exists)"
                )
            return [sys.executable, str(script)], None
        if not callable(run):
            raise ConfigError(
                f"Study: run={run!r}: give a function f(output, **parameters) or a script's path"
            )
        import inspect

        try:
            signature = inspect.signature(run)
        except (TypeError, ValueError):
            signature = None
        for index, row in enumerate(self.rows):
            try:
                if signature is not None:
                    signature.bind(self.output, **row)
            except TypeError as exc:
                name = getattr(run, "__name__", "run")
                raise ConfigError(f"Study: {name}(output, **row {index}) does not fit: {exc}") from None
        try:
            import cloudpickle
        except ImportError as exc:
            raise UnsupportedFeature(
                f"Study of a function needs cloudpickle (Dask's): {cluster.INSTALL}; or give a script's path"
            ) from exc
        code = "from pygran_core.simulation.study import child; child()"
        return [sys.executable, "-c", code], cloudpickle.dumps(run)

    def _open_journal(self, resume: bool) -> dict[str, Any]:
        path = self.output / JOURNAL
        if not path.is_file():
            return {"runs": {}}
        if not resume:
            raise ConfigError(
                f"Study: {self.output} holds a study already ({JOURNAL}); pass resume=True to continue "
                "it, or choose another output folder"
            )
        try:
            journal = json.loads(path.read_text())
            recorded = journal["runs"]
        except (ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"Study: {path} is damaged ({exc}); move it away to start afresh") from None
        for key, entry in recorded.items():
            index = int(key)
            if index >= len(self.rows) or entry["parameters"] != self.rows[index]:
                now = self.rows[index] if index < len(self.rows) else "no row"
                raise ConfigError(
                    f"Study: run {index} ran with {entry['parameters']} but the table now gives {now}; "
                    "a resumed study keeps its rows (add new rows at the end)"
                )
        return dict(journal)

    def folder(self, index: int) -> Path:
        """The output folder of run ``index``."""
        return self.output / f"run{index}"

    def run(self) -> list[dict[str, Any]]:
        """Run every row not finished yet; return the table's rows (also in ``results.csv``)."""
        self.output.mkdir(parents=True, exist_ok=True)
        with _exclusive(self.output / LOCK):
            return self._run()

    def _run(self) -> list[dict[str, Any]]:
        runs: dict[str, Any] = self.journal["runs"]
        pending = [i for i in range(len(self.rows)) if runs.get(str(i), {}).get("status") != "done"]
        for i in pending:
            runs[str(i)] = {"parameters": self.rows[i], "status": "pending", "attempts": 0}
        self._save()
        with self._bar(len(self.rows) - len(pending)) as bar:
            for outcome in self._outcomes(pending):
                entry = runs[str(outcome.index)]
                entry["attempts"] += 1
                entry["seconds"] = round(outcome.seconds, 3)
                entry.update(
                    {"status": "done", "results": outcome.results, "error": ""}
                    if outcome.ok
                    else {"status": "failed", "results": {}, "error": outcome.error}
                )
                self._save()
                if outcome.ok or entry["attempts"] > self.retries:
                    bar.update(1)
                failed = sum(e["status"] == "failed" and e["attempts"] > self.retries for e in runs.values())
                bar.set_postfix_str(f"failed {failed}" if failed else "")
        table = self.table()
        failed = [f"run {row['run']} ({row['error']})" for row in table if row["status"] == "failed"]
        if failed:
            attempts = "1 attempt" if self.retries == 0 else f"{self.retries + 1} attempts"
            warnings.warn(
                f"Study: {len(failed)} of {len(table)} runs failed after {attempts}: "
                f"{'; '.join(failed)}. Their logs: {self.output}/run<i>/{LOG}; the table: "
                f"{self.output / TABLE}",
                PyGranWarning,
                stacklevel=3,
            )
        return table

    def _outcomes(self, pending: list[int]) -> Iterator[Outcome]:
        """Each attempt's outcome as it comes, failed runs submitted again while tries remain."""
        tries = self.retries + 1
        if cluster.is_serial(self.client):
            for i in pending:
                for _ in range(tries):
                    outcome = self._attempt(i)
                    yield outcome
                    if outcome.ok:
                        break
            return
        with cluster.connect(self.client, self.workers, "Study") as client:
            dd = cluster.distributed("Study")
            attempts = {i: 1 for i in pending}
            runs = {self._submit(client, i, 1): i for i in pending}
            queue = dd.as_completed(runs)
            for future in queue:
                try:
                    outcome = future.result()
                except Exception as exc:  # noqa: BLE001 - a lost worker fails its run, not the study
                    outcome = Outcome(runs[future], False, 0.0, error=f"its Dask task failed: {exc!r}")
                yield outcome
                if not outcome.ok and attempts[outcome.index] < tries:
                    attempts[outcome.index] += 1
                    again = self._submit(client, outcome.index, attempts[outcome.index])
                    runs[again] = outcome.index
                    queue.add(again)

    def _attempt(self, index: int) -> Outcome:
        folder = str(self.folder(index))
        return execute(index, folder, self.rows[index], self._command, self._function, self.timeout)

    def _submit(self, client: Any, index: int, attempt: int) -> Any:
        folder = str(self.folder(index))
        key = f"pygran-study-{os.getpid()}-{id(self)}-run{index}-try{attempt}"
        return client.submit(
            execute, index, folder, self.rows[index], self._command, self._function, self.timeout, key=key
        )

    def _bar(self, done: int) -> Any:
        from tqdm import tqdm

        show = self.progress if self.progress is not None else sys.stderr.isatty()
        return tqdm(total=len(self.rows), initial=done, unit="run", desc="study", disable=not show)

    def _save(self) -> None:
        _write_json(self.output / JOURNAL, self.journal)
        _write_atomically(self.output / TABLE, _csv(self.table()))

    def table(self) -> list[dict[str, Any]]:
        """One row per run so far: ``run``, its parameters, ``status`` (done, failed, pending),
        ``attempts``, ``seconds``, its results and its last ``error``."""
        rows = []
        for key, entry in sorted(self.journal["runs"].items(), key=lambda item: int(item[0])):
            rows.append(
                {
                    "run": int(key),
                    **entry["parameters"],
                    "status": entry["status"],
                    "attempts": entry["attempts"],
                    "seconds": entry.get("seconds"),
                    **entry.get("results", {}),
                    "error": entry.get("error", ""),
                }
            )
        return rows


def _csv(rows: list[dict[str, Any]]) -> str:
    columns = list(dict.fromkeys(key for row in rows for key in row))
    columns.append(columns.pop(columns.index("error")))
    text = io.StringIO()
    writer = csv.DictWriter(text, columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: json.dumps(v) if isinstance(v, (dict, list)) else v for k, v in row.items()})
    return text.getvalue()
