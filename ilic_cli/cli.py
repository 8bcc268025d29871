"""The ``ilic`` command line: a thin layer that parses, calls and renders.

Subcommands live in :mod:`ilic_cli.commands` and are imported only when run,
so ``ilic --help`` stays instant. Errors follow one contract: bad input or
usage -> ``ilic: error: FILE: problem`` on stderr and exit 2; an internal
failure -> exit 1 (``--debug`` shows the traceback); Ctrl-C -> 130;
SIGTERM -> 143. Output files are written atomically by the commands.
"""

from __future__ import annotations

import atexit
import importlib
import os
import signal
import sys
import threading
import traceback
from typing import Any, NoReturn

import click

from ilic_cli import __version__
from ilic_cli.errors import IlicError
from ilic_cli.parallel import one_blas_thread, threads

COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("ilic_cli.commands.simulate", "Simulate the EMPS axis in closed loop and write a log."),
    "replay": ("ilic_cli.commands.replay", "Replay a log's recorded reference through the plant."),
    "identify": ("ilic_cli.commands.identify", "Identify M, Fv, Fc, offset by IDIM-LS and IDIM-ILIC."),
    "diagnose": ("ilic_cli.commands.diagnose", "Find and model the physics a simulation leaves out."),
    "convert": ("ilic_cli.commands.convert", "Convert a log between .mat, CSV, MCAP and ROS bags."),
    "info": ("ilic_cli.commands.info", "Summarise a log: duration, rate, channels, ranges, quality."),
    "batch": ("ilic_cli.commands.batch", "Identify (and diagnose) many logs into one table, resumably, locally or on Dask."),
    "trend": ("ilic_cli.commands.trend", "Trend a batch table's parameters per machine: steps, slopes, payload swaps."),
}


class Terminated(BaseException):
    """Raised from the SIGTERM handler so that atomic writers clean up."""


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        module = importlib.import_module(COMMANDS[cmd_name][0])
        command: click.Command = module.command
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, help_) for name, (_, help_) in COMMANDS.items()])


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="ilic")
@click.option("--debug", is_flag=True, help="Show the full traceback of an error.")
def cli(debug: bool) -> None:
    """Identify, simulate and diagnose a drive axis from its logged runs.

    \b
    Typical use:
      ilic info run.mcap                       what is in a log
      ilic identify run.mat --out report/      IDIM-LS and IDIM-ILIC estimates
      ilic simulate --scenario paper-sim -o sim.mcap
      ilic diagnose run.mat                    what the model leaves out

    Logs: EMPS .mat, CSV, MCAP, ROS 1 .bag, ROS 2 bag folders.
    """


HELP_ASKED = frozenset({"-h", "--help", "--version"})
"""Arguments that only ask for help or the version: answered whatever the environment says."""


M_ARENA_MAX = -8
"""glibc's ``mallopt`` parameter for the most heaps (arenas) its threads allocate from."""


def _one_heap() -> None:
    """One glibc heap for every thread of the ``ilic`` process (``mallopt(M_ARENA_MAX, 1)``), set before any thread starts.

    The filters' blocks and the replays run in threads; with a heap of its own each kept the freed blocks of arrays of
    the log's length: ``ilic identify --method both`` on a 1-hour 1 kHz MCAP peaked at 531-585 MB from run to run, 416 MiB
    with one heap, at 0.87x the CPU (measured on issue 33's log). The command line owns its process, so it is set here,
    not by the library's readers. Not glibc: nothing to do.
    """
    # ctypes (some 3 ms) deferred: a command's work, not --help's
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt(M_ARENA_MAX, 1)
    except (OSError, AttributeError):
        pass


def _on_sigterm(signum: int, frame: Any) -> None:
    raise Terminated()


def main(argv: list[str] | None = None) -> None:
    """Run the command line and exit with the status of the error contract."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    try:
        signal.signal(signal.SIGTERM, _on_sigterm)
        signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C even when started with SIGINT ignored
    except ValueError:  # not in the main thread (tests)
        pass
    status = 0
    one_blas_thread()  # the same bits on any machine's cores: the command line owns its process, and numpy has not loaded
    try:
        if not HELP_ASKED.intersection(args):
            threads()  # a bad $ILIC_THREADS is refused before any work (help is no work)
            _one_heap()
        cli.main(args=args, prog_name="ilic", standalone_mode=False)
    except IlicError as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"ilic: error: {exc.message()}", err=True)
        status = 2
    except click.UsageError as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if exc.ctx else ""
        click.echo(f"ilic: error: {exc.format_message()}{hint}", err=True)
        status = 2
    except click.ClickException as exc:
        click.echo(f"ilic: error: {exc.format_message()}", err=True)
        status = exc.exit_code if exc.exit_code else 1
    except (KeyboardInterrupt, click.Abort):
        click.echo("ilic: interrupted", err=True)
        status = 130
    except Terminated:
        click.echo("ilic: terminated", err=True)
        status = 143
    except BrokenPipeError:
        status = 0
    except Exception as exc:  # internal failure
        if debug:
            traceback.print_exc()
        click.echo(f"ilic: error: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)", err=True)
        status = 1
    sys.exit(status)


def run() -> NoReturn:
    """The ``ilic`` process (``python -m ilic_cli``, the ``ilic`` script): :func:`main`, then the process ends without the interpreter's teardown.

    After a command Python's finalisation frees every module's objects one by
    one; with numba loaded (``ilic simulate``, the identifiers' filters) that
    took 0.20-0.24 s of CPU after ``ilic simulate --duration 300``'s work
    (0.84-0.90 s of user CPU with it, 0.63-0.66 s without; 3 paired runs), a
    fifth of the process. Here the process ends as Python's would, less the
    freeing: non-daemon threads joined and the ``atexit`` functions run (what
    the interpreter calls first at exit), stdout and stderr flushed (a failed
    flush exits 120, as Python does), then :func:`os._exit` with the status.
    Files are closed by the commands, which write them atomically.
    """
    try:
        main()
        status = 0
    except SystemExit as exc:
        code = exc.code
        if code is None or isinstance(code, int):
            status = code or 0
        else:  # as Python prints a non-integer exit code
            print(code, file=sys.stderr)
            status = 1
    shutdown = getattr(threading, "_shutdown", None)  # the interpreter's first step at exit: join non-daemon threads and executors' workers
    if shutdown is not None:
        shutdown()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream
            status = status or 120
    os._exit(status)
