"""flexmodal command line: a thin dispatcher over the packages.

Every sub-command comes from the command registry (cli.commands.COMMANDS: each entry adds its
sub-commands to the parser and imports its heavy dependencies only when the command runs).  Errors of
the one family ``flexmodal.checked_io.errors.FlexmodalError`` (each package raises its subclass), and
operating-system errors (a missing or unreadable file, a full disk) become one line on stderr and exit
code 2 (docs/formats.md).
"""

from __future__ import annotations

import argparse
import codecs
import os
import signal
import sys
import threading
import traceback
from collections.abc import Sequence

from flexmodal import __version__
from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.cli.commands import COMMANDS


class UsageError(Exception):
    """A command-line usage mistake (unknown option, bad option value)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP met by the command (``acquire`` handles them itself while it records): raised
    where Ctrl-C raises KeyboardInterrupt, so that an output being written is removed as after Ctrl-C,
    and the command ends with one line and exit code 128 + N (it ended silently with 143 or 129)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
_MAIN_PID = os.getpid()


def _terminate(signum: int, _frame) -> None:
    if os.getpid() != _MAIN_PID:   # a helper forked from the command inherits this handler: it ends as
        signal.signal(signum, signal.SIG_DFL)   # it would by default
        os.kill(os.getpid(), signum)
        return
    raise Terminated(signum)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) and exit 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: error: {message}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="flexmodal",
        description="Experimental modal analysis and data acquisition for flexible robot arms.",
    )
    parser.add_argument("--quiet", action="store_true", help="silence progress output on stderr")
    parser.add_argument("--version", action="version", version=f"flexmodal {__version__}",
                        help="print flexmodal's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for add in COMMANDS.values():   # the command registry (cli.commands.COMMANDS), in its order
        add(sub)
    for command in sub.choices.values():  # `flexmodal CMD --quiet` works as well as `flexmodal --quiet CMD`
        try:
            command.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS,
                                 help="silence progress output on stderr")
        except argparse.ArgumentError:  # the command has a --quiet of its own (sim serve)
            pass
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the process exit code (0 ok, 2 bad input, 1 internal error, 128 + N stopped
    by signal N: 130 for Ctrl-C).

    Handlers registered by the packages take the parsed namespace and return an exit code; they
    must write results only to stdout and progress/logs only to stderr (docs/formats.md).
    """
    if argv is None:  # after a Ctrl-C this process ends with os._exit; multiprocessing's resource tracker
        # (a child that dask's LocalCluster starts, launched with our -W options) would then print a
        # multi-line warning about the semaphores it cleans up after us, below our one line
        sys.warnoptions.append("ignore::UserWarning:multiprocessing.resource_tracker")
        sys.unraisablehook = _interrupt_again
    if argv is None:  # the command's own streams, maybe in ASCII or Latin-1 (LANG, PYTHONIOENCODING):
        _escape_what_cannot_be_shown()  # Δ, ζ, µ shown as \u0394 ..., not a UnicodeEncodeError
        global _MAIN_PID
        _MAIN_PID = os.getpid()
        for s in STOP_SIGNALS:   # SIGTERM, SIGHUP: as Ctrl-C, with their own line (unless ignored: nohup)
            if signal.getsignal(s) == signal.SIG_DFL:
                signal.signal(s, _terminate)
    if sys.stdout is None:  # started with stdout closed (`>&-`): the result would have nowhere to go
        _say("flexmodal: error: standard output is closed: the command's result is printed there (redirect "
             "it, e.g. > result.txt, or to /dev/null)")
        return 2
    try:
        args = build_parser().parse_args(argv)
        _check_environment()
        return int(args.func(args) or 0)
    except UsageError as exc:
        _say(str(exc))
        return 2
    except FlexmodalError as exc:  # one line even when a quoted library message had several
        _say(f"flexmodal: error: {' '.join(str(exc).split())}")
        signum = getattr(exc, "signum", 0)  # stopped by a signal before any work (daq.acquire.Stopped)
        return 128 + signum if signum else 2
    except OSError as exc:  # missing or unreadable files, a full disk, an I/O error: named, one line
        where = _where(exc)
        if isinstance(exc, BrokenPipeError) and where == "standard output: ":
            _stdout_gone()   # `flexmodal compare ... | head`: the reader took what it wanted
            return 0
        _say(f"flexmodal: error: {where}{' '.join(str(exc.strerror or exc).split())}")
        return 2
    except (KeyboardInterrupt, Exception) as exc:
        signum = _from_interrupt(exc)
        if not signum:  # a bug: the traceback, exit 1
            raise
        if argv is None:  # the command itself: outputs are closed or removed by now, so skip the
            _leave_interrupted(signum)  # interpreter's tear-down (seconds of garbage collection after a demo)
        _say(_stopped_line(signum))
        return 128 + signum
    finally:
        if argv is None:  # done: a Ctrl-C during the interpreter's tear-down still ends it the same way
            for s in (signal.SIGINT, *STOP_SIGNALS):
                if signal.getsignal(s) != signal.SIG_IGN:
                    signal.signal(s, lambda signum, _frame: _leave_interrupted(signum))


def _check_environment() -> None:
    """UsageError naming an environment variable a library refuses on import, before any work: an
    MPLBACKEND matplotlib does not know made every command that draws end in a ValueError traceback."""
    backend = os.environ.get("MPLBACKEND")
    if backend:
        try:
            import matplotlib  # noqa: F401 - its import validates MPLBACKEND
        except ValueError:
            raise UsageError(f"flexmodal: error: environment variable MPLBACKEND={backend!r} is not a "
                             "matplotlib backend (unset it, or set MPLBACKEND=Agg)") from None


def _escape_what_cannot_be_shown() -> None:
    """Let stdout and stderr write a character their encoding lacks as a backslash escape (``Δ`` in an
    ASCII or Latin-1 stream: ``\u0394``) instead of raising UnicodeEncodeError after the work is done."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None and hasattr(stream, "reconfigure"):
            try:
                if codecs.lookup(stream.encoding).name != "utf-8":
                    stream.reconfigure(errors="backslashreplace")
            except (LookupError, TypeError, ValueError, OSError):  # a stream of its own kind: left as it is
                continue


def _stdout_gone() -> None:
    """Point stdout at /dev/null once its reader has gone (a closed pipe), so that the interpreter's
    last flush of what is left in its buffer does not report a second BrokenPipeError at exit."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):   # not a file of its own (a test's capture)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)


def _where(exc: OSError) -> str:
    """What an operating-system error is about, as the start of its line: the file it names; else the
    current folder when that is gone (deleted under the command), else standard output when the error
    came from a line writing the result there (a full disk, /dev/full); else nothing."""
    if exc.filename is not None:
        return f"{exc.filename}: "
    try:
        os.getcwd()
    except FileNotFoundError:
        return "the current folder no longer exists (deleted or moved; cd to one that exists): "
    for frame in traceback.extract_tb(exc.__traceback__):
        code = frame.line or ""
        if "sys.stdout" in code or ("print(" in code and "file=" not in code):
            return "standard output: "   # the handler's own write of its result failed there
    return ""


def _say(message: str) -> None:
    """``message`` as one line on stderr; a stderr that is gone (its terminal closed, its pipe's reader
    ended) is no second error: the exit code still tells the outcome.  Characters that are not printable
    (control characters quoted from a binary file: ESC would drive the terminal) are written escaped."""
    message = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in message)
    try:
        print(message, file=sys.stderr, flush=True)
    except OSError:
        pass


def _from_interrupt(exc: BaseException) -> int:
    """The signal (SIGINT for Ctrl-C, or that of :class:`Terminated`) when ``exc`` is a stop, or an error
    a library raised from one (a KeyboardInterrupt met while a class body was set up during an import
    comes back as RuntimeError, "Error calling __set_name__", caused by it); else 0."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return getattr(exc, "signum", signal.SIGINT)
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return 0


def _stopped_line(signum: int) -> str:
    return ("flexmodal: interrupted" if signum == signal.SIGINT else
            f"flexmodal: stopped by {signal.Signals(signum).name}")


def _interrupt_again(unraisable) -> None:
    """``sys.unraisablehook`` of the command: a Ctrl-C that lands in a garbage-collector or weakref
    callback is reported and dropped by Python ("Exception ignored in: ..."), and the command would run
    on to its end; deliver it again from a helper thread instead (it retries if it lands in one again),
    so that the command stops.  Any other unraisable exception is reported as Python does."""
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        signum = getattr(unraisable.exc_value, "signum", signal.SIGINT)
        threading.Timer(0.01, os.kill, (os.getpid(), signum)).start()
        return
    sys.__unraisablehook__(unraisable)


def _leave_interrupted(signum: int = signal.SIGINT) -> None:
    """Say so on stderr, end the child processes and end this one at once with exit code 128 +
    ``signum`` (130 for Ctrl-C)."""
    _say(_stopped_line(signum))
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except OSError:  # a closed terminal or pipe: nothing more can reach it
            pass
    _close_hdf5_files()
    _end_children()
    os._exit(128 + signum)


def _close_hdf5_files() -> None:
    """Close every HDF5 file this process still has open, so that none keeps its open-for-writing
    superblock flags after ``os._exit`` (which skips h5py's clean-up).  Writers open and close their
    files with Ctrl-C deferred; this catches any file a signal left open anyway."""
    h5py = sys.modules.get("h5py")  # not imported: no file to close
    if h5py is None:
        return
    for fid in h5py.h5f.get_obj_ids(types=h5py.h5f.OBJ_FILE):
        try:
            h5py.File(fid).close()
        except Exception:  # noqa: BLE001 - ending anyway: close what can be closed
            continue


def _end_children() -> None:
    """SIGTERM every child process (dask nannies, a simulator, an eigen worker), so that none outlives
    the command by the second or more it would take to notice (Linux /proc; multiprocessing's resource
    tracker ignores SIGTERM and still cleans up after us)."""
    me = os.getpid()
    try:
        pids = [int(p) for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", "rb") as fh:
                parent = int(fh.read().rsplit(b")", 1)[1].split()[1])
            if parent == me:
                os.kill(pid, signal.SIGTERM)
        except (OSError, ValueError, IndexError):
            continue


if __name__ == "__main__":
    sys.exit(main())
