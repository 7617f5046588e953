"""Sphinx configuration of the shipsense documentation.

Build (from the repository's root, with the ``docs`` extra installed)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html

Everything a page shows that comes from the code is made by this build: the API reference (one page per
public module, found by walking the package), the scenario reference (``docs/_ext/shipsense_docs.py`` reads
the pydantic models), the command-line reference (the argparse parser) and the gallery (sphinx-gallery
runs ``docs/gallery/*.py`` at small sizes and keeps the figures they draw).  Nothing generated is
committed: ``docs/_build``, ``docs/api/generated`` and ``docs/auto_gallery`` are build output.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))            # the checkout's shipsense, not another installed copy
sys.path.insert(0, str(DOCS / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

import shipsense  # noqa: E402

project = "shipsense"
author = "the shipsense developers"
copyright = "the shipsense developers, MIT licence"
release = version = shipsense.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "shipsense_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "gallery/GALLERY_HEADER.rst", "**.ipynb_checkpoints", "auto_gallery/*.ipynb",
                    "auto_gallery/*.py", "auto_gallery/*.zip", "auto_gallery/*.json", "auto_gallery/*.codeobj.json"]

# -- cross-references: a reference to a name that does not exist fails the build (-W) -----------------------
nitpicky = True
default_role = "literal"   # the docstrings' single backticks are code, as in the README
nitpick_ignore_regex = [
    # base classes from other packages, named by show-inheritance (gymnasium.Env, gymnasium's VectorEnv,
    # SB3's VecEnv, sb3-contrib's maskable policy, torch's Module, numpy's SeedSequence, concurrent.futures.Future,
    # argparse's parser, pydantic's BaseModel):
    # their inventories would be fetched from
    # the network, which the build does not use.  A reference to a shipsense name is never ignored.
    ("py:class", r"(gymnasium|stable_baselines3|sb3_contrib|torch|numpy|concurrent\.futures|argparse|pydantic)\..+"),
]

# -- API reference: shipsense_docs.generate_api writes one page per public module at every build ------------
autodoc_default_options = {"members": True, "show-inheritance": True, "member-order": "bysource"}
autodoc_inherit_docstrings = False   # gymnasium's Env.step/reset/render docstrings are not this project's
autodoc_typehints = "none"      # the docstrings state types, shapes and units; the signatures stay readable
autodoc_mock_imports: list[str] = []
add_module_names = False
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()
numpydoc_attributes_as_param_list = True

# -- gallery: the experiments at small sizes, run by every build --------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": ["gallery"],
    "gallery_dirs": ["auto_gallery"],
    "filename_pattern": r"/plot_",
    "abort_on_example_error": True,      # a failing example fails the build
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "plot_gallery": "True",
    "capture_repr": (),
    "image_scrapers": ("matplotlib",),
    "min_reported_time": 1,
    "matplotlib_animations": False,
}

# -- HTML: the pydata theme (the scientific Python projects' theme: numpy, scipy, pandas, matplotlib) -------
html_theme = "pydata_sphinx_theme"
html_title = f"shipsense {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "navbar_align": "left",
    "header_links_before_dropdown": 7,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_sidebars = {"index": [], "getting-started": []}
html_static_path: list[str] = []
html_show_sourcelink = False

myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

