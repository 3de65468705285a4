"""Write the capability matrix (hevsim.capabilities) into docs/simulate.md between its markers.

    .venv/bin/python scripts/capability_matrix.py           # rewrite the page's matrix
    .venv/bin/python scripts/capability_matrix.py --check   # exit 1 when the page is stale

The matrix is derived from the architecture registry and the file schema, never typed by hand;
tests/test_capability_matrix.py fails when the page and the generated matrix differ.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hevsim.capabilities import update_docs

PAGE = Path(__file__).resolve().parents[1] / "docs" / "simulate.md"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 when the page is stale")
    args = parser.parse_args()
    current = update_docs(PAGE, write=not args.check)
    if args.check and not current:
        print(
            f"{PAGE}: the capability matrix is stale; run python scripts/capability_matrix.py",
            file=sys.stderr,
        )
        return 1
    print(f"{PAGE}: capability matrix {'up to date' if current else 'rewritten'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
