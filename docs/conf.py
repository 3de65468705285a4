"""Sphinx configuration of the hevsim documentation site (issue 28).

One site from the repository: the user guides (the Markdown pages of ``docs/``, MyST), the
executed tutorial gallery (``docs/tutorials/*.py``, sphinx-gallery), the how-to guides
(``docs/howto/``) and the API reference (``docs/api/``, from the docstrings).

Build: ``make docs`` (``python -m sphinx -W --keep-going -b html docs docs/_build/html``);
``make test`` builds it with warnings as errors. Offline: no intersphinx, no remote images.
"""

from __future__ import annotations

import importlib.metadata
import os

os.environ.setdefault("MPLBACKEND", "Agg")

project = "hevsim"
author = "hevsim contributors"
copyright = "hevsim contributors, BSD-3-Clause"
release = importlib.metadata.version("hevsim")
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",  # the Google-style "Args:" / "Returns:" sections
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# --- API reference (docs/api) -----------------------------------------------------------------
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

# --- tutorial gallery (docs/tutorials -> docs/auto_tutorials) ----------------------------------
# Every script is executed at each build (its output and figures go into its page), in
# docs/tutorials, where `examples` links to the repository's examples/ so that the scripts'
# paths are those of a reader in the repository's root. The
# scripts use short cycles and coarse grids so that the whole gallery stays within a couple of
# minutes on two cores; hevsim's compiled kernels are cached on disk (numba) between builds.
sphinx_gallery_conf = {
    "examples_dirs": ["tutorials"],
    "gallery_dirs": ["auto_tutorials"],
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"/_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "min_reported_time": 1,
    "show_memory": False,
    "plot_gallery": "True",
    "write_computation_times": False,
}

# --- pages ------------------------------------------------------------------------------------
exclude_patterns = [
    "_build",
    "tutorials/README.txt",
    "tutorials/examples",  # a link to the repository's examples/, for the tutorials' relative paths
    "**/.ipynb_checkpoints",
    "sg_execution_times.rst",
]
html_theme = "alabaster"
html_title = f"hevsim {release}"
html_static_path = ["_static"]
html_theme_options = {
    "description": "Open Python toolkit for hybrid-electric vehicle engineering",
    "fixed_sidebar": False,
    "page_width": "1100px",
}
