import os
import subprocess
import sys


def in_fresh_interpreter(code: str, drop: tuple[str, ...] = (), cwd=None, **env) -> str:
    """The last line ``code`` prints in a new interpreter (in the folder ``cwd``, first on its
    path), run without the environment variables whose names start with one of ``drop`` and with
    ``env`` added."""
    base = {k: v for k, v in os.environ.items() if not k.startswith(drop)}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True,
                         check=True, cwd=cwd)
    return out.stdout.strip().splitlines()[-1]
