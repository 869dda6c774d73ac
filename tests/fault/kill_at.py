"""Run the inkopt command line in this process and SIGKILL it just before its Nth file replacement (``os.replace``,
which every atomic write ends with), as a crash or ``kill -9`` at that moment would: the new content is whole in
its temporary file, not yet in place. ``python kill_at.py N inkopt-args...``; N = 0 never kills. Writes the number
of replacements the command made to stderr as its last line (``replacements: K``)."""

import os
import signal
import sys


def main() -> int:
    kill_at, argv = int(sys.argv[1]), sys.argv[2:]
    calls = 0
    replace = os.replace

    def replace_or_die(src, dst, **kw):
        nonlocal calls
        calls += 1
        if calls == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        return replace(src, dst, **kw)

    os.replace = replace_or_die
    from inkopt.cli import main as inkopt

    code = inkopt(argv)
    print(f"replacements: {calls}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
