"""Make safety-gymnasium 1.0.0 importable on Python 3.11 (oracle venv only, never the project).

Python 3.11's dataclasses reject unhashable defaults, and safety-gymnasium 1.0.0 declares its
objects' colours as ``color: np.array = COLOR['goal']`` (a NumPy array default), so
``import safety_gymnasium`` raises ``ValueError: mutable default <class 'numpy.ndarray'> for
field color is not allowed``. This rewrites each such line to
``color: np.array = dataclasses.field(default_factory=lambda: COLOR['goal'])``, which returns
the very same array object, so behaviour is unchanged. Idempotent.

Usage (see README.md): <oracle venv>/bin/python patch_safety_gymnasium.py
"""

from __future__ import annotations

import re
from importlib.util import find_spec
from pathlib import Path

PATTERN = re.compile(r"^(\s+color: np\.array = )(COLOR\['\w+'\])\s*$", re.M)


def main() -> None:
    spec = find_spec("safety_gymnasium")
    assert spec is not None and spec.origin is not None, "safety_gymnasium is not installed"
    root = Path(spec.origin).parent
    patched = []
    for path in sorted(root.rglob("*.py")):
        text = path.read_text()
        new = PATTERN.sub(r"\1dataclasses.field(default_factory=lambda: \2)", text)
        if new != text:
            # Beside the module's own dataclasses import (after its docstring and
            # ``from __future__`` line, if any).
            assert "\nfrom dataclasses import" in new, path
            new = new.replace("\nfrom dataclasses import", "\nimport dataclasses\nfrom dataclasses import", 1)
            path.write_text(new)
            patched.append(path.relative_to(root))
    print(f"patched {len(patched)} files: {', '.join(map(str, patched)) or '(already patched)'}")


if __name__ == "__main__":
    main()
