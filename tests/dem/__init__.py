import os
import subprocess
import sys


def in_fresh_interpreter(code: str, drop: tuple[str, ...] = (), **env) -> str:
    """The last line ``code`` prints in a new interpreter, run without the environment variables
    whose names start with one of ``drop`` and with ``env`` added."""
    base = {k: v for k, v in os.environ.items() if not k.startswith(drop)}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True,
                         check=True)
    return out.stdout.strip().splitlines()[-1]
