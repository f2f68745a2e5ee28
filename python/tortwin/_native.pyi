"""Type stubs of the extension module ``tortwin._native`` (python/src/lib.rs).

Every function takes the command's argument list as the ``tortwin`` command
line would (parsed by the binary's own clap definitions, without the program
name) and a configuration as ``(kind, value, name)``: ``("file", path, "")``
or ``("toml", text, name)``. A bad argument or input raises
:class:`InputError` with the message the binary prints; anything else that
stops a job raises :class:`TortwinError`. The package's typed functions in
``tortwin/__init__.py`` build these calls; use those.
"""

Config = tuple[str, str, str]

class TortwinError(Exception):
    """A job that could not finish (the command line's exit status 1)."""

class InputError(TortwinError):
    """Bad input or an impossible request (the command line's exit status 2)."""

def replay(
    argv: list[str],
    config: Config | None = None,
    state_json: str | None = None,
    field: bool = True,
    per_train: bool = False,
) -> tuple[str, str, bytes, bytes | None, bytes, bytes | None]:
    """``tortwin replay ARGV``: the summary (JSON), the end state (JSON), and
    the measurements, field (unless ``field`` is false), trains and, with
    ``per_train``, per-train metrics tables as Arrow IPC streams."""

def synth(argv: list[str], truth_config: Config | None = None) -> tuple[str, str]:
    """``tortwin synth ARGV``: the key (JSON) and the path of the key file."""

def discover(argv: list[str], config: Config | None = None) -> tuple[str, bytes]:
    """``tortwin discover ARGV``: report.json's text and the residual table
    (Arrow IPC)."""

def calibrate(argv: list[str], config: Config | None = None) -> tuple[str, bytes]:
    """``tortwin calibrate ARGV``: report.json's text and the residual table
    (Arrow IPC)."""

def strategy(argv: list[str], config: Config | None = None) -> str:
    """``tortwin strategy ARGV``: the path of strategy.json."""

def split(argv: list[str]) -> list[tuple[str, str]]:
    """``tortwin split ARGV``: the days written, ``(YYYY-MM-DD, path)`` in
    time order."""

def merge(argv: list[str]) -> int:
    """``tortwin merge ARGV``: the messages written."""

class Live:
    """``tortwin live ARGV`` following on a thread of its own."""

    def next(self) -> str | None:
        """The next JSON line (a train's rail band, an alert, a recording
        finished), waiting for it; ``None`` once the follow ended."""

    def close(self) -> None:
        """Stops the follow and waits for its thread."""

def live(argv: list[str], config: Config | None = None) -> Live:
    """Starts ``tortwin live ARGV``: its lines come from :meth:`Live.next`."""

def version() -> str:
    """The version of the library crates the module was built from."""
