# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The documentation as a product: the site builds with every link and anchor resolved, the
docs stay a user's manual, and a user's install holds no developer's tool.

The commands the docs show are tests of their own (conftest.py at the repository's root runs
every block of README.md and docs/*.md); this module checks the rest."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'
PAGES = [ROOT / 'README.md', *sorted(DOCS.glob('*.md'))]
#: the docs' size: a manual a user reads, not a record of how it came to be
MAX_DOCS_LINES = 3500


#: The folder beside a clone that a page must never point to (a clone has no such folder).
OUTSIDE = '../' + 'shared'


def _sphinx(source: Path, out: Path, conf: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q', '-b', 'html',
         '-c', str(conf), str(source), str(out)],
        capture_output=True, text=True, timeout=300)


def test_the_site_builds_with_every_link_and_anchor_resolved(tmp_path):
    """`python -m sphinx -W -b html -c docs . DIR`: a missing page, file or heading anchor is a
    warning, and -W fails the build on it."""
    out = _sphinx(ROOT, tmp_path / 'site', DOCS)
    assert out.returncode == 0, f'the docs site does not build:\n{out.stderr[-6000:]}'
    assert (tmp_path / 'site' / 'docs' / 'index.html').is_file()
    assert (tmp_path / 'site' / 'README.html').is_file()


def test_a_broken_anchor_fails_the_build(tmp_path):
    """The check itself: the same configuration on two pages, one linking to a heading the other
    does not have."""
    (tmp_path / 'docs').mkdir()
    (tmp_path / 'README.md').write_text('# Readme\n\n[node](docs/node.md#running-it)\n')
    (tmp_path / 'docs' / 'index.md').write_text('# Index\n\n```{toctree}\n/README\nnode\n```\n')
    (tmp_path / 'docs' / 'node.md').write_text('# Node\n\n## Running\n\ntext\n')
    out = _sphinx(tmp_path, tmp_path / 'site', DOCS)
    assert out.returncode != 0
    assert "'running-it'" in out.stderr and 'README.md' in out.stderr, out.stderr
    (tmp_path / 'docs' / 'node.md').write_text('# Node\n\n## Running it\n\ntext\n')
    assert _sphinx(tmp_path, tmp_path / 'site2', DOCS).returncode == 0


def test_the_docs_are_a_manual():
    """Present tense for a user: at most MAX_DOCS_LINES lines in docs/, no word of how the work
    was organised, no tracker numbers, no link out of the repository's own text."""
    lines = sum(len(p.read_text().splitlines()) for p in DOCS.glob('*.md'))
    assert lines <= MAX_DOCS_LINES, f'docs/ has {lines} lines (at most {MAX_DOCS_LINES})'
    banned = re.compile(r'\b(sessions?|helpers?|agents?)\b', re.IGNORECASE)
    tracker = re.compile(r'\bissues? \d+', re.IGNORECASE)
    found = []
    for page in PAGES:
        for number, line in enumerate(page.read_text().splitlines(), 1):
            for pattern in (banned, tracker):
                if pattern.search(line):
                    found.append(f'{page.relative_to(ROOT)}:{number}: {line.strip()[:80]}')
            if OUTSIDE in line:
                found.append(f'{page.relative_to(ROOT)}:{number}: links out of the repository')
    assert not found, '\n'.join(found)


def test_every_figure_is_shown_somewhere():
    """A file in docs/figures/ that no page links to is left over: delete it."""
    text = ''.join(p.read_text() for p in PAGES)
    unused = [str(f.relative_to(DOCS)) for f in sorted((DOCS / 'figures').rglob('*'))
              if f.is_file() and str(f.relative_to(DOCS)) not in text]
    assert not unused, f'figures no page links to: {unused}'



def test_every_doc_the_code_names_exists():
    """A comment or docstring that sends the reader to a page of docs/ (the package, the tests, the
    benchmarks, the scripts) names a page that is there."""
    missing = []
    for folder in ('worm_gear_sim', 'test', 'benchmarks', 'scripts'):
        for path in sorted((ROOT / folder).rglob('*.py')):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                for name in re.findall(r'docs/([\w.-]+\.md)', line):
                    if not (DOCS / name).is_file():
                        missing.append(f'{path.relative_to(ROOT)}:{number}: docs/{name}')
    assert not missing, 'pages that do not exist:\n' + '\n'.join(missing)

#: A file of the repository named in backquotes (``a/b.py``, ``a/b_*.py``, ``a/b.py:name``).
FILE_NAMED = re.compile(r'`([\w.*/-]+/[\w.*-]+\.(?:py|sh|yaml|yml|md|png|csv|npz|json|toml|txt))'
                        r'(?::\w+)?`')


def test_every_file_the_docs_name_exists():
    """A path the pages name in backquotes, under a folder of the repository or of the package
    (``realtime/predictor.py``), is there (a glob matches at least one file); a path under
    another folder is an output the page describes (``pass/pass.png``) and is not checked."""
    package = ROOT / 'worm_gear_sim'
    missing = []
    for page in PAGES:
        for name in FILE_NAMED.findall(page.read_text()):
            first = name.split('/', 1)[0]
            bases = [b for b in (ROOT, package) if (b / first).is_dir()]
            if bases and not any(any(b.glob(name)) for b in bases):
                missing.append(f'{page.relative_to(ROOT)}: {name}')
    assert not missing, 'files that do not exist:\n' + '\n'.join(missing)


DEV_TOOLS = {'pytest', 'pytest-xdist', 'hypothesis', 'mypy', 'ruff', 'colcon-core', 'sphinx',
             'myst-parser', 'sybil'}


def _names(path: Path) -> set[str]:
    names = set()
    for line in path.read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line and not line.startswith('-'):
            names.add(re.split(r'[\s\[<>=!~;]', line, maxsplit=1)[0].lower())
    return names


def test_a_users_install_holds_no_developers_tool():
    """scripts/setup_env.sh installs requirements.txt and the distro's ROS wheels (what the
    demo and a user get); the test, lint and docs tools are requirements/dev.txt, which only
    `scripts/setup_env.sh --dev` (scripts/run_tests.sh) adds.  Nothing the run-time set needs
    pulls a tool in either (from the installed packages' own requirements)."""
    from importlib.metadata import PackageNotFoundError, requires
    runtime = _names(ROOT / 'requirements.txt')
    for ros in (ROOT / 'requirements').glob('ros-*.txt'):
        runtime |= _names(ros)
    assert not runtime & DEV_TOOLS, sorted(runtime & DEV_TOOLS)
    assert DEV_TOOLS <= _names(ROOT / 'requirements' / 'dev.txt')
    script = (ROOT / 'scripts' / 'setup_env.sh').read_text()
    assert 'requirements/dev.txt' in script and '--dev' in script
    assert 'scripts/setup_env.sh --dev' in (ROOT / 'scripts' / 'run_tests.sh').read_text()
    for user_script in ('run_demo.sh', 'run_pass.sh'):
        calls = [ln.split('#', 1)[0].split() for ln in
                 (ROOT / 'scripts' / user_script).read_text().splitlines()
                 if ln.startswith('scripts/setup_env.sh')]
        assert calls and all(c == ['scripts/setup_env.sh'] for c in calls), (user_script, calls)
    # the closure of the run-time requirements, as installed here
    seen, todo = set(), runtime | {'distributed'}
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            reqs = requires(name) or []
        except PackageNotFoundError:
            continue
        for req in reqs:
            if 'extra ==' in req:
                continue
            todo.add(re.split(r'[\s\[<>=!~;(]', req, maxsplit=1)[0].lower().replace('_', '-'))
    assert not seen & DEV_TOOLS, f'the run-time requirements pull in {sorted(seen & DEV_TOOLS)}'
