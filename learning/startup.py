"""The first thing an orcgym command does: Ctrl-C during its imports (torch, MuJoCo: seconds) is one line.

Standard library only, so that it is in place before the slow imports start. train.py, play.py and
sweep.py call `quiet_ctrl_c_at_startup` first, and analysis/__init__.py does for every
`python -m analysis.<module>`. Once a command's main runs, learning.cli.run handles Ctrl-C itself.
"""

from __future__ import annotations

import os
import sys


def quiet_ctrl_c_at_startup() -> None:
    """An uncaught KeyboardInterrupt prints one line instead of its traceback (exit status 130, as before).

    Only a Ctrl-C that nothing caught reaches this hook, i.e. one before main; --debug keeps the traceback.
    """
    previous = sys.excepthook
    if getattr(previous, "quiet_ctrl_c", False):
        return  # installed already (sweep.py imports train.py)

    def hook(kind, value, traceback) -> None:
        if issubclass(kind, KeyboardInterrupt) and "--debug" not in sys.argv:
            program = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "python"
            print(f"\n{program}: interrupted while starting up; nothing was written (run the command again)",
                  file=sys.stderr)
            return
        previous(kind, value, traceback)

    hook.quiet_ctrl_c = True
    sys.excepthook = hook
