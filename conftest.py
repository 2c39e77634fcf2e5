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
* Directives in HTML comments right before a block (invisible on GitHub and on the site),
  applied when the tests are collected, so that they hold under ``-k`` and ``-m`` too:
  ``<!-- skip: next "why it cannot run in CI" -->`` (Sybil's markup) skips the block with its
  reason; ``<!-- docs-test: env NAME=VALUE ... -->`` runs it with those variables (the
  documented small case of a script, e.g. its duration); ``<!-- docs-test: xfail "reason" -->``
  marks it as expected to fail (a known defect being fixed; XPASS once it passes).
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
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from markdown_it import MarkdownIt
from sybil import Document, Example, Lexeme, Region, Sybil
from sybil.parsers.markdown import CodeBlockParser
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


def _stop_group(proc: subprocess.Popen) -> tuple[str, str]:
    """SIGINT to the example's process group, SIGKILL 10 s later; what it printed."""
    for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGKILL, 10.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            return proc.communicate(timeout=wait)
        except subprocess.TimeoutExpired:
            continue
    return '', ''


def _run(example: Example, argv: list[str]) -> str | None:
    """Run one block; None when it succeeded, else the failure's text."""
    work = example.namespace['work']
    source = str(example.parsed)
    env = _environment(source)
    env.update(directives(example.document.text, example.region.start).get('env', {}))
    # its own session: at the timeout every process it started is stopped, not only the shell
    with subprocess.Popen(argv + [source], cwd=work, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          preexec_fn=_limit_file_size, start_new_session=True) as proc:
        try:
            stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            stdout, stderr = _stop_group(proc)
            return (f'still running after {TIMEOUT_S:.0f} s: an example must finish in '
                    f'seconds\n--- stdout (end) ---\n{stdout[-3000:]}\n'
                    f'--- stderr (end) ---\n{stderr[-3000:]}')
    if proc.returncode != 0:
        return (f'exit status {proc.returncode}\n--- stdout (end) ---\n{stdout[-3000:]}\n'
                f'--- stderr (end) ---\n{stderr[-3000:]}')
    written = _directory_bytes(work)
    if written > MAX_DIR_BYTES:
        return (f'the examples wrote {written / 2**20:.1f} MiB: a documented example writes at '
                f'most a few MB')
    return None


def _evaluate_bash(example: Example) -> str | None:
    return _run(example, ['bash', '-e', '-o', 'pipefail', '-c'])


def _evaluate_python(example: Example) -> str | None:
    return _run(example, [sys.executable, '-c'])


def _evaluate_yaml(example: Example) -> None:
    import yaml
    yaml.safe_load(str(example.parsed))


COMMENT = re.compile(r'<!--\s*(skip|docs-test):\s*(.*?)\s*-->\s*$', re.DOTALL)


def _parse_directive(kind: str, arguments: str) -> dict:
    words = shlex.split(arguments)
    if kind == 'skip' and len(words) == 2 and words[0] == 'next':
        return {'skip': words[1]}
    if kind == 'docs-test' and len(words) > 1 and words[0] == 'env' \
            and all('=' in w for w in words[1:]):
        return {'env': dict(w.split('=', 1) for w in words[1:])}
    if kind == 'docs-test' and len(words) == 2 and words[0] == 'xfail':
        return {'xfail': words[1]}
    raise ValueError(f'unknown directive <!-- {kind}: {arguments} -->: write skip: next "reason", '
                     'docs-test: env NAME=VALUE ..., or docs-test: xfail "reason"')


def directives(text: str, start: int) -> dict:
    """The directives of the HTML comments that stand right before the block at ``start``."""
    found: dict = {}
    head = text[:start].rstrip()
    while head.endswith('-->'):
        opening = head.rfind('<!--')
        match = COMMENT.match(head[opening:])
        if opening < 0 or match is None:
            break
        found.update(_parse_directive(match.group(1), match.group(2)))
        head = head[:opening].rstrip()
    return found


def _evaluate_directive(example: Example) -> None:
    _parse_directive(*example.parsed)


class DirectiveParser:
    """Each ``skip:`` / ``docs-test:`` comment is checked for its syntax (a typo fails)."""

    def __init__(self) -> None:
        self.lexers = [DirectiveInHTMLCommentLexer(directive=kind, arguments='.+?')
                       for kind in ('skip', 'docs-test')]

    def __call__(self, document: Document):
        for lexer, kind in zip(self.lexers, ('skip', 'docs-test')):
            for region in lexer(document):
                region.parsed = (kind, region.lexemes['arguments'])
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
    parsers=[DirectiveParser(), FenceCheckParser(),
             _code('bash', _evaluate_bash), _code('python', _evaluate_python),
             _code('yaml', _evaluate_yaml)],
    patterns=['README.md', 'docs/*.md'],
    path=str(ROOT),
    setup=_setup,
    teardown=_teardown,
).pytest()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The directives before each block become its marks (skip, xfail); a block that starts
    ROS 2 is marked ``ros`` (the Jazzy run repeats it)."""
    for item in items:
        example = getattr(item, 'example', None)
        if example is None or not isinstance(example.parsed, (str, Lexeme)):
            continue
        found = directives(example.document.text, example.region.start)
        if 'skip' in found:
            item.add_marker(pytest.mark.skip(reason=found['skip']))
        if 'xfail' in found:
            item.add_marker(pytest.mark.xfail(reason=found['xfail'], strict=False))
        if ROS_WORDS.search(str(example.parsed)):
            item.add_marker(pytest.mark.ros)
