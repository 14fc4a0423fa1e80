"""How messages name what the user can set: in the API's words, spelt by the front end in use.

Errors, warnings and advice below the command line name a setting by its place in the API:

- a setting of the pipeline's config by ``section.field`` (``refine.max_outer``,
  ``matching.guess_pairs``; :data:`nbcalib.config.SECTIONS`), ``seed`` alone;
- an input of the job by ``inputs.field`` (``inputs.every``, ``inputs.frames``: the fields of
  :class:`~nbcalib.preprocess.inputs.InputSpec`);
- a choice of how the job runs by ``run.name`` (``run.init``, ``run.force``, ``run.until``:
  :meth:`Calibrator.run <nbcalib.pipeline.Calibrator.run>`'s arguments, the ``[run]`` table of a
  config file).

``name=value`` gives a value (``refine.max_outer=20``). The API's user reads these names as
they are. The command line (:func:`nbcalib.cli.main`) installs its spelling
(:func:`spelling`), which writes each as the flag that sets it (``--max-outer 20``) from its one
Option table (:mod:`nbcalib.commands._options`), so that its user reads ``--every``.
:class:`~nbcalib.errors.InputError`, :class:`~nbcalib.errors.RegistrationFailed` and the
report's reasons and advice are spelt when made (:func:`say`); the command line's log handler
spells the log lines.

This module imports nothing of nbcalib: every room may use it.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Iterator, Mapping

__all__ = ["API_NAME", "say", "spelling", "translator"]

#: An API name in a message: ``section.field``, ``inputs.field`` or ``run.name`` (the section
#: part is checked against the table by :func:`translator`, so file names are left alone).
API_NAME = re.compile(r"(?<![\w.\-])([a-z][a-z_]*)\.([a-z][a-z0-9_]*)\b(=?)")

_spell: Callable[[str], str] | None = None


def say(text: str) -> str:
    """``text`` as the front end in use spells setting names (unchanged for the API)."""
    return text if _spell is None else _spell(text)


@contextlib.contextmanager
def spelling(spell: Callable[[str], str] | None) -> Iterator[None]:
    """Spell messages with ``spell`` while the block runs (the command line: its flags).

    A process-wide setting, not a context variable: messages made in worker threads
    (:func:`nbcalib._threads.thread_map`) are spelt the same way. The previous spelling is back
    afterwards, so an API call after a command in the same process reads API names again.
    """
    global _spell
    before, _spell = _spell, spell
    try:
        yield
    finally:
        _spell = before


def translator(flags: Mapping[str, str]) -> Callable[[str], str]:
    """A spelling that writes each API name of ``flags`` as its flag.

    ``flags`` maps ``"refine.max_outer"`` to ``"--max-outer"``; ``name=value`` becomes
    ``flag value``; other words stay as they are.
    """

    def replace(match: re.Match) -> str:
        name = f"{match.group(1)}.{match.group(2)}"
        flag = flags.get(name)
        if flag is None:
            return match.group(0)
        return flag + (" " if match.group(3) else "")

    def spell(text: str) -> str:
        return API_NAME.sub(replace, text)

    return spell
