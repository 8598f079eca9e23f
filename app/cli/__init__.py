"""The ``rig`` command line: thin sub-commands over library functions.

This package and :mod:`app.demo` are the application layer: they may import every package
(lazily, so ``rig --help`` stays fast); the library packages keep to the boundaries of
``docs/architecture.md``. Here are the parser and :func:`main`; each command family has its
module (its parser and its handler): :mod:`app.cli.sample`, :mod:`app.cli.demo`,
:mod:`app.cli.relight`, :mod:`app.cli.view`, :mod:`app.cli.export`, :mod:`app.cli.rig`
(``doctor``, ``sim start``), :mod:`app.cli.plan`, :mod:`app.cli.advise`,
:mod:`app.cli.evaluate`, :mod:`app.cli.fit`, :mod:`app.cli.batch`, :mod:`app.cli.bench`,
:mod:`app.cli.capture` (``capture``, ``verify``, ``export-lp``), :mod:`app.cli.calibrate`,
:mod:`app.cli.process` and :mod:`app.cli.sim`; the argument types are :mod:`app.cli.args` and
the names offered as choices :mod:`app.cli.choices`.
"""

from __future__ import annotations

import argparse
import contextlib
import faulthandler
import os
import select
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from types import FrameType

from app.cli.advise import add_advise
from app.cli.args import check_file_arguments
from app.cli.batch import add_batch
from app.cli.bench import add_bench_parser
from app.cli.calibrate import add_calibrate
from app.cli.capture import add_capture
from app.cli.demo import add_demo
from app.cli.evaluate import add_evaluate
from app.cli.export import add_export_web
from app.cli.fit import add_fit
from app.cli.plan import add_plan
from app.cli.process import add_process
from app.cli.relight import add_relight
from app.cli.rig import add_doctor
from app.cli.sample import add_sample
from app.cli.sim import add_sim
from app.cli.view import add_view
from core.errors import RigError
from core.progress import drawing_bars

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The ``rig`` argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="rig",
        description="Reflectance-field capture rig and controllable image-based relighting.",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_sample(commands)
    add_demo(commands)
    add_relight(commands)
    add_view(commands)
    add_export_web(commands)
    add_doctor(commands)
    add_plan(commands)
    add_advise(commands)
    add_evaluate(commands)
    add_fit(commands)
    add_batch(commands)
    add_bench_parser(commands)
    add_capture(commands)
    add_calibrate(commands)
    add_process(commands)
    add_sim(commands)
    _quiet_everywhere(parser)
    return parser


def _quiet_everywhere(parser: argparse.ArgumentParser) -> None:
    """Give every command that lacks its own ``--quiet`` one (no progress bars).

    Any command may report progress through the library, so every one takes the flag a
    script passes to silence it; commands that say more about theirs define it themselves.
    argparse has no public walk over its sub-commands, hence its private ``_actions``.
    """
    nested = [
        action for action in parser._actions if isinstance(action, argparse._SubParsersAction)
    ]
    if not nested:
        if not any("--quiet" in action.option_strings for action in parser._actions):
            parser.add_argument("--quiet", action="store_true", help="no progress bars")
        return
    for action in nested:
        for command in dict.fromkeys(action.choices.values()):  # aliases repeat a parser
            _quiet_everywhere(command)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rig`` console script; returns the exit status.

    A bad argument is refused by argparse (its message, status 2) and returned as the
    status, like every other refusal, rather than leaving by ``SystemExit``. Ctrl-C and
    SIGTERM both unwind the command (see :func:`_unwind_on_sigterm`): what it created is
    removed, a line on stderr says it was stopped, and the status is the shell's convention,
    128 + the signal's number (130, 143), unless the command handles the stop itself (``rig
    view``, ``rig capture``) and returns its own. The library's progress is drawn on stderr
    (:func:`_drawing_progress`).
    """
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as leaving:  # argparse's error (2) and --help (0)
        return leaving.code if isinstance(leaving.code, int) else 2
    except BrokenPipeError:  # --help into a closed pipe
        if not _stdout_gone():
            raise
        _silence_stdout()
        return 128 + signal.SIGPIPE
    # `kill -USR1 PID` prints every thread's stack on stderr: what a command that seems stuck
    # is doing (the signal tests ask for it before giving up on a process).
    if sys.__stderr__ is not None:  # a process with no stderr (embedded) has no stacks to print
        faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)
    with _unwind_on_sigterm() as received:
        try:
            check_file_arguments(args)  # a FIFO or a device would block or never end
            with _drawing_progress(args):
                status: int = args.handler(args)
        except RigError as error:
            print(f"rig {args.command}: error: {error}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            number = received[-1] if received else signal.SIGINT
            word = "terminated" if number == signal.SIGTERM else "interrupted"
            print(f"rig {args.command}: {word}", file=sys.stderr)
            return 128 + number
        except BrokenPipeError:
            if not _stdout_gone():
                raise
            # What reads the output stopped reading (`rig sim scenes --json | head -1`): stop
            # quietly, as a command ended by SIGPIPE does; nothing more can reach it.
            _silence_stdout()
            return 128 + signal.SIGPIPE
    return status


def _drawing_progress(args: argparse.Namespace) -> contextlib.AbstractContextManager[object]:
    """Draw the library's progress bars on stderr while the command runs, unless ``--quiet``.

    The library only reports its work (:mod:`core.progress`); here it is drawn, a tqdm bar for
    each bar under way, closed when the command ends however it ends.
    """
    if getattr(args, "quiet", False):
        return contextlib.nullcontext()
    return drawing_bars()


def _stdout_gone() -> bool:
    """Whether standard output is a pipe whose reader has closed it."""
    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # replaced (a test's capture), or closed
        return False
    poller = select.poll()
    poller.register(descriptor, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _silence_stdout() -> None:
    """Point standard output at /dev/null: the interpreter's final flush has nowhere to fail."""
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, sys.stdout.fileno())
    finally:
        os.close(null)


@contextlib.contextmanager
def _unwind_on_sigterm() -> Iterator[list[int]]:
    """SIGTERM raises :class:`KeyboardInterrupt` in the main thread while the block runs.

    By default SIGTERM ends the process where it stands: no ``finally`` or ``with`` runs, so
    a temporary field store (an RTI capture's import), the viewer's uploads or a half-written
    output would stay behind. Raised as Ctrl-C is, it unwinds through the same cleanups and
    the same ``except KeyboardInterrupt`` of the commands that catch it. Yields the list the
    signals received are appended to, so the caller can tell SIGTERM from Ctrl-C. Another
    SIGTERM during that unwinding is ignored: a supervisor repeating its request must not cut
    the cleanup short (SIGKILL is the way to not wait).
    """
    received: list[int] = []

    def terminate(number: int, frame: FrameType | None) -> None:
        received.append(number)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        # A signal handler can only be set from the main thread (a test calling main()
        # from a worker): SIGTERM keeps its default there.
        yield received
        return
    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, previous)
