# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Sphinx + MyST configuration of the docs site (the Markdown of README.md and docs/).

    python -m sphinx -W --keep-going -b html -c docs . build/site

The source directory is the repository's root, so that README.md is a page of the site and
its links into docs/ are checked like the others; only README.md and docs/ are read.  A link
to a missing page, file or heading anchor is a warning, and -W makes it an error
(test/test_docs.py builds the site this way)."""

project = 'worm_gear_sim'
author = 'worm_gear_sim developers'
copyright = '2026, worm_gear_sim developers'
extensions = ['myst_parser']
root_doc = 'docs/index'
source_suffix = {'.md': 'markdown'}
include_patterns = ['README.md', 'docs/*.md', 'docs/figures/**']
exclude_patterns = ['.*', '_build', 'build', 'install', 'log', 'benchmarks', 'config', 'launch',
                    'resource', 'requirements', 'rosdep', 'scripts', 'test', 'urdf',
                    'worm_gear_sim', 'docs/conf.py']
# Every heading gets a GitHub-style anchor (the links work on GitHub and on the site alike);
# a link to an anchor that no heading makes is reported (myst.xref_missing).
myst_heading_anchors = 4
myst_enable_extensions = ['dollarmath']
html_theme = 'alabaster'
html_title = 'worm_gear_sim'
