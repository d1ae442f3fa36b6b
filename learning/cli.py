"""What the orcgym command lines share: one flag style, values checked as they are parsed, one error path.

train.py, play.py, sweep.py and the analysis modules build their parsers from `Parser` and the
`add_*` groups here and run their bodies through `run` (tools/ and bench/ use plain argparse), so that:
  * flags are spelled with underscores (`--num_envs`, `--max_per_config`); the dashed spelling of
    a flag is accepted too (`--max-per-config`);
  * a bad flag value is one line naming the flag, the value and what is allowed, before anything
    is built or written (argparse's usage block is left to --help);
  * no exception reaches the user as a traceback: problems with the inputs are one line
    (exit 1), anything unexpected is one line naming the exception (exit 1, `--debug` shows the
    traceback), and Ctrl-C that reaches here exits quietly with status 130.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any, Callable

from gym_envs.config import ConfigError, yaml_text
from gym_envs.orc import ORC_FORMAT, is_orc_string

EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors, a --debug flag and dashed aliases of underscore flags."""

    def __init__(self, prog: str, doc: str, **kwargs: Any):
        super().__init__(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs)
        self.add_argument("--debug", action="store_true", help="show the full traceback of an error")

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {' '.join(message.split())}; see {self.prog} --help\n")

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        return super().parse_known_args([self._underscored(a) for a in args], namespace)

    def _underscored(self, token: str) -> str:
        if not token.startswith("--"):
            return token
        flag, eq, value = token.partition("=")
        spelled = flag.replace("-", "_").replace("__", "--", 1)
        return spelled + eq + value if spelled in self._option_string_actions else token


# --- value types: each raises a one-line argparse error naming what is allowed -----------------------


def integer(low: int | None = None) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or (low is not None and value < low):
            raise argparse.ArgumentTypeError(
                f"{text!r} is not allowed; use an integer" + (f" >= {low}" if low is not None else ""))
        return value

    parse.__name__ = "integer"
    return parse


def number(low: float | None = None, low_open: bool = False) -> Callable[[str], float]:
    """A finite float, above `low` (strictly when low_open)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        too_low = low is not None and (value <= low if low_open else value < low)
        if not math.isfinite(value) or too_low:
            bound = "" if low is None else f" {'>' if low_open else '>='} {low:g}"
            raise argparse.ArgumentTypeError(f"{text!r} is not allowed; use a finite number{bound}")
        return value

    parse.__name__ = "number"
    return parse


def orc(text: str) -> str:
    if not is_orc_string(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not an ORC string; use {ORC_FORMAT}")
    return text


def folder(text: str) -> str:
    """A folder to read from or write into: it may not exist yet, but it may not be a file."""
    if not text or os.path.isfile(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed; use a folder path (not an existing file)")
    return text


def check_writable(path: str, flag: str = "--out") -> None:
    """Make folder `path` and write a file into it, or a one-line ConfigError: before hours of work, not after."""
    import tempfile

    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as err:
        raise ConfigError(f"{flag} {path} cannot be written ({err.strerror or err}); choose a folder you can "
                          f"write into") from None


def new_file(suffix: str) -> Callable[[str], str]:
    """A file to write: `suffix` as its extension, in a folder that exists."""
    def parse(text: str) -> str:
        parent = os.path.dirname(text) or "."
        if not text.endswith(suffix) or not os.path.isdir(parent):
            raise argparse.ArgumentTypeError(f"{text!r} is not allowed; use a {suffix} file in an existing folder")
        return text

    parse.__name__ = "file"
    return parse


def name(text: str) -> str:
    """An experiment or run name: one plain folder name."""
    if not text or os.sep in text or text in (".", ".."):
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed; use a plain folder name (no path separator)")
    return text


# --- flag groups ----------------------------------------------------------------------------------


def add_run_selection(p: argparse.ArgumentParser, what: str) -> None:
    """--load_run, --checkpoint, --experiment_name, --log_root: which run `what` uses."""
    p.add_argument("--load_run", help=f"run to {what}: a folder name in the experiment, or a path")
    p.add_argument("--checkpoint", type=integer(-1), default=-1, help="iteration to load (-1: the newest)")
    p.add_argument("--experiment_name", type=name, help="experiment folder under the log root")
    p.add_argument("--log_root", type=folder, help="folder of experiments (default: $ORCGYM_LOG_ROOT or <repo>/logs)")


def add_compute(p: argparse.ArgumentParser, device_default: str | None = None) -> None:
    """--device, --sim, --num_threads; without device_default, training's defaults that fit the machine."""
    machine = device_default is None  # learning/machine.py chooses
    p.add_argument("--device", choices=("cpu", "cuda"), default=device_default,
                   help="task tensors and networks (default: "
                        + ("cuda when torch sees a CUDA device, else cpu)" if machine else f"{device_default})"))
    p.add_argument("--sim", choices=("mujoco", "warp"),
                   help="physics backend, sets sim.backend (default: "
                        + ("warp on cuda when the gpu extra is installed, else mujoco)" if machine
                           else "mujoco on cpu, the run's on cuda)"))
    p.add_argument("--num_threads", type=integer(0), help="CPU threads of the physics and of torch (0: all cores)")


def add_overrides(p: argparse.ArgumentParser, help_text: str) -> None:
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=help_text)


def add_print_config(p: argparse.ArgumentParser) -> None:
    p.add_argument("--print_config", action="store_true",
                   help="print the resolved env and train config as YAML (keys as --set takes them) and exit")


def config_yaml(env_cfg: Any, train_cfg: Any) -> str:
    """Both configs as one YAML mapping whose keys are those --set takes: env sections, and train.<key>."""
    from gym_envs.config import to_dict

    return yaml_text({**to_dict(env_cfg), "train": to_dict(train_cfg)})


# --- the one error path ----------------------------------------------------------------------------


def one_line(err: BaseException) -> str:
    return " ".join(str(err).split())


def input_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean bad input (a config, a file, a run): reported as they are, one line."""
    from gym_envs.sim import SimSetupError

    return ConfigError, SimSetupError, OSError


def run(parser: Parser, body: Callable[[argparse.Namespace], int | None], argv: list[str] | None = None) -> int:
    """Parse argv and return body(args)'s exit status; every failure becomes one line on stderr."""
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help, or a malformed flag (its line is printed): a status, as everywhere else
        return int(done.code or 0)
    try:
        return body(args) or 0
    except (KeyboardInterrupt, Exception) as err:  # noqa: BLE001 - the one place that turns any failure into a line
        if args.debug:
            raise
        if isinstance(err, KeyboardInterrupt):
            print(f"\n{parser.prog}: interrupted; stopped without saving", file=sys.stderr)
            return EXIT_INTERRUPTED
        if isinstance(err, input_errors()):
            print(f"{parser.prog}: error: {one_line(err)}", file=sys.stderr)
        else:
            print(f"{parser.prog}: error: {type(err).__name__}: {one_line(err)} (unexpected; --debug shows the "
                  f"traceback)", file=sys.stderr)
        return EXIT_ERROR
