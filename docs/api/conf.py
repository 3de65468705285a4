"""Sphinx configuration of the hevsim API reference (built from the docstrings).

Build: ``python -m sphinx -W --keep-going -b html docs/api build/api-html`` (or ``make docs``).
"""

from __future__ import annotations

import importlib.metadata

project = "hevsim"
author = "hevsim contributors"
copyright = "hevsim contributors, BSD-3-Clause"
release = importlib.metadata.version("hevsim")
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",  # the Google-style "Args:" / "Returns:" sections
]

# The package is installed (editable) with its dependencies: nothing is mocked, so a module
# that does not import fails the build.
autodoc_default_options = {
    "members": True,
    "member-order": "bysource",
    "show-inheritance": True,
}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True  # show `DEFAULT_X`, not its repr, in signatures
autoclass_content = "both"  # class docstring + __init__ docstring
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# The docstrings write ``x`` for code; a bare `x` is the default role, shown as code too.
default_role = "code"

exclude_patterns = ["_build"]
html_theme = "alabaster"
html_title = f"hevsim {release} API reference"
html_static_path: list[str] = []
