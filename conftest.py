# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Every documented command is a test: Sybil collects the fenced blocks of README.md and
docs/*.md, and each runs as a user would run it.

* ```` ```bash ```` blocks run in ``bash -e -o pipefail``, ```` ```python ```` blocks in a fresh
  interpreter of this venv (``python -c``), ```` ```yaml ```` blocks must parse; ```` ```text ````
  blocks are shown, not run (what a command prints); ```` ```{directive} ```` blocks belong to
  the site (MyST).  Any other fence, and an indented code block, fails: a command must sit in a
  block that runs.
* Each document runs in a temporary directory of its own, its blocks in order (a block may use
  the files an earlier one wrote); ``.venv`` (and ``.venv-jazzy``) there is this interpreter's
  venv, ``config/``, ``scripts/``, ``benchmarks/``, ``launch/`` and ``urdf/`` the repository's,
  so the commands read as they do from a clone's root.  ``worm-gear-sim`` and the other
  console scripts are on the PATH.
* Examples are small: a file larger than ``MAX_FILE_BYTES`` ends its command (RLIMIT_FSIZE),
  a document's directory may not hold more than ``MAX_DIR_BYTES`` after a block, and a block
  may not run longer than ``TIMEOUT_S``.
* Directives in an HTML comment before a block (invisible on GitHub and on the site):
  ``<!-- skip: next "why it cannot run in CI" -->`` (Sybil's own) leaves the next block out,
  with its reason in the test report; ``<!-- docs-test: env NAME=VALUE ... -->`` runs the next
  block with those variables (the documented small case of a script, e.g. its duration);
  ``<!-- docs-test: xfail "reason" -->`` expects the next block to fail (a known defect
  being fixed: it fails the block with the reason as xfail, and warns when it passes).
* A block that starts ROS 2 (``ros2``, ``rclpy``, ``worm_gear_sim.ros``, the ROS console
  scripts, ``scripts/run_*.sh``) is marked ``ros``, so that the Jazzy run of CI repeats it; it
  runs on ``ROS_DOMAIN_ID`` + 1 with discovery on localhost, as the tests' child processes.
"""

from __future__ import annotations

import os
import re
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import pytest
from markdown_it import MarkdownIt
from sybil import Document, Example, Region, Sybil
from sybil.parsers.markdown import CodeBlockParser, SkipParser
from sybil.parsers.markdown.lexers import DirectiveInHTMLCommentLexer

ROOT = Path(__file__).resolve().parent
#: what a command finds in its working directory, as in a clone's root
LINKED = ('config', 'scripts', 'benchmarks', 'launch', 'urdf')
MAX_FILE_BYTES = 16 * 2**20
MAX_DIR_BYTES = 48 * 2**20
TIMEOUT_S = 180.0
RUN_LANGUAGES = ('bash', 'python', 'yaml')
SHOWN_LANGUAGES = ('text',)
ROS_WORDS = re.compile(r'\bros2\b|rclpy|worm_gear_sim\.ros|worm_gear_sim_(node|pedestal|'
                       r'calibrate|demo)|scripts/run_(demo|pass)\.sh')


def _setup(namespace: dict) -> None:
    work = Path(tempfile.mkdtemp(prefix='docs-example-'))
    venv = Path(sys.prefix)
    for name in ('.venv', '.venv-jazzy'):
        (work / name).symlink_to(venv)
    for name in LINKED:
        (work / name).symlink_to(ROOT / name)
    namespace['work'] = work
    namespace['options'] = {}


def _teardown(namespace: dict) -> None:
    shutil.rmtree(namespace['work'], ignore_errors=True)


def _limit_file_size() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (MAX_FILE_BYTES, MAX_FILE_BYTES))


def _environment(source: str) -> dict[str, str]:
    env = dict(os.environ)
    env['PATH'] = f'{Path(sys.executable).parent}{os.pathsep}{env.get("PATH", "")}'
    env['MPLBACKEND'] = 'Agg'
    env['PYTHONUNBUFFERED'] = '1'
    env.pop('VENV', None)
    if ROS_WORDS.search(source):
        env['ROS_DOMAIN_ID'] = str(int(env.get('ROS_DOMAIN_ID', '42') or 42) + 1)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        env.pop('ROS_STATIC_PEERS', None)
    return env


def _directory_bytes(path: Path) -> int:
    """Bytes of the files an example wrote (the links to the venv and the repository apart)."""
    total = 0
    for folder, _, files in os.walk(path):       # does not follow the links
        total += sum(os.lstat(os.path.join(folder, f)).st_size for f in files)
    return total


def _run(example: Example, argv: list[str]) -> str | None:
    """Run one block; None when it succeeded, else the failure's text."""
    ns = example.namespace
    options = ns['options']
    ns['options'] = {}
    source = str(example.parsed)
    env = _environment(source)
    env.update(options.get('env', {}))
    try:
        proc = subprocess.run(argv + [source], cwd=ns['work'], env=env, text=True,
                              capture_output=True, timeout=TIMEOUT_S,
                              preexec_fn=_limit_file_size)
        failure = None
        if proc.returncode != 0:
            failure = (f'exit status {proc.returncode}\n--- stdout (end) ---\n'
                       f'{proc.stdout[-3000:]}\n--- stderr (end) ---\n{proc.stderr[-3000:]}')
    except subprocess.TimeoutExpired:
        failure = f'still running after {TIMEOUT_S:.0f} s: an example must finish in seconds'
    written = _directory_bytes(ns['work'])
    if failure is None and written > MAX_DIR_BYTES:
        failure = (f'the examples wrote {written / 2**20:.1f} MiB: a documented example writes '
                   f'at most a few MB')
    if 'xfail' in options:
        if failure is not None:
            pytest.xfail(options['xfail'])
        warnings.warn(f'{example.path}:{example.line}: the block marked xfail '
                      f'({options["xfail"]}) passes now: remove the mark', stacklevel=1)
    return failure


def _evaluate_bash(example: Example) -> str | None:
    return _run(example, ['bash', '-e', '-o', 'pipefail', '-c'])


def _evaluate_python(example: Example) -> str | None:
    return _run(example, [sys.executable, '-c'])


def _evaluate_yaml(example: Example) -> None:
    import yaml
    yaml.safe_load(str(example.parsed))


def _evaluate_directive(example: Example) -> None:
    words = shlex.split(example.parsed)
    options = example.namespace['options']
    if words[0] == 'env' and len(words) > 1 and all('=' in w for w in words[1:]):
        options['env'] = dict(w.split('=', 1) for w in words[1:])
    elif words[0] == 'xfail' and len(words) == 2:
        options['xfail'] = words[1]
    else:
        raise ValueError(f'unknown docs-test directive: {example.parsed!r} '
                         '(env NAME=VALUE ... | xfail "reason")')


class DirectiveParser:
    """``<!-- docs-test: ... -->``: options for the next block."""

    def __init__(self) -> None:
        self.lexer = DirectiveInHTMLCommentLexer(directive='docs-test', arguments='.+?')

    def __call__(self, document: Document):
        for region in self.lexer(document):
            region.parsed = region.lexemes['arguments']
            region.evaluator = _evaluate_directive
            yield region


class FenceCheckParser:
    """A block that cannot run and is not marked as output: a fence of another language (or of
    none) and an indented code block are each a failing example naming the block."""

    def __call__(self, document: Document):
        lines = document.text.splitlines(keepends=True)
        starts = [0]
        for line in lines:
            starts.append(starts[-1] + len(line))
        for token in MarkdownIt('commonmark').parse(document.text):
            if token.type == 'fence':
                language = token.info.strip().split(' ')[0]
                if language in RUN_LANGUAGES + SHOWN_LANGUAGES or language.startswith('{'):
                    continue                   # '{toctree}': a directive of the site
                problem = (f'a ```{language} block: write a command as ```bash or ```python '
                           f'(it runs), what it prints as ```text')
            elif token.type == 'code_block':
                problem = 'an indented code block: write it fenced (```bash, ```text, ...)'
            else:
                continue
            first, last = token.map
            yield Region(starts[first], starts[last], problem, _fail)


def _fail(example: Example) -> str:
    return str(example.parsed)


def _code(language: str, evaluator):
    return CodeBlockParser(language=language, evaluator=evaluator)


pytest_collect_file = Sybil(
    parsers=[SkipParser(), DirectiveParser(), FenceCheckParser(),
             _code('bash', _evaluate_bash), _code('python', _evaluate_python),
             _code('yaml', _evaluate_yaml)],
    patterns=['README.md', 'docs/*.md'],
    path=str(ROOT),
    setup=_setup,
    teardown=_teardown,
).pytest()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A documented block that starts ROS 2 is marked ``ros`` (the Jazzy run repeats it)."""
    for item in items:
        example = getattr(item, 'example', None)
        if example is not None and ROS_WORDS.search(str(example.parsed)):
            item.add_marker(pytest.mark.ros)
