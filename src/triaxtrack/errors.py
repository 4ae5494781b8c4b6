"""Errors a user can act on: configuration and test.yaml problems in words, and why a job failed.

* :func:`schema_problems` turns JSON-schema errors into one line each, naming the file that
  holds the key, the key's place (``tests[0].simulate.seed``) and, for a near miss, "did you
  mean ...?" (:func:`did_you_mean`), never the schema itself.
* :func:`unknown_top_level_keys` finds keys a schema allows but does not read (a typo such as
  ``frame:`` for ``frames:`` in test.yaml), for a warning.
* :func:`failed_jobs` and :func:`job_log_reason` read Snakemake's own log and the failed jobs'
  logs for the Snakefile's ``onerror`` handler: the exception message instead of a traceback.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jsonschema

__all__ = [
    "did_you_mean",
    "failed_jobs",
    "format_failed_jobs",
    "job_log_reason",
    "schema_problems",
    "source_of",
    "unknown_top_level_keys",
]

#: difflib's similarity ratio a key must reach to be suggested: 0.6 (difflib's default) takes
#: `chunksize` -> `chunk_size` (0.95) and `frame` -> `frames` (0.91), not `fps` -> `name`.
SUGGEST_CUTOFF = 0.6
MAX_PROBLEMS = 10  # problems listed; the rest are counted
MAX_VALUE_CHARS = 60  # a value longer than this is shortened in a message
MAX_REASON_LINES = 6  # lines of a failed job's exception message shown on the console
TAIL_LINES = 4  # lines shown from the end of a log without a Python traceback


def did_you_mean(word: object, choices: Iterable[object]) -> str:
    """``"; did you mean 'x'?"`` for the closest of ``choices`` to ``word`` (difflib's ratio; among
    equals, an anagram first, so ``h246`` gives ``h264``; still tied: all of them), else ""."""
    word, options = str(word), [str(c) for c in choices]
    matches = difflib.get_close_matches(word, options, n=max(len(options), 1), cutoff=SUGGEST_CUTOFF)
    if not matches:
        return ""

    def closeness(option: str) -> tuple[float, bool]:
        return difflib.SequenceMatcher(None, word, option).ratio(), sorted(option) == sorted(word)

    best = max(closeness(m) for m in matches)
    return f"; did you mean {' or '.join(repr(m) for m in matches if closeness(m) == best)}?"


def key_path(path: Sequence[object]) -> str:
    """A place in a document as a user writes it: ``tests[0].simulate.seed`` (``()``: "top level")."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return f"`{text}`" if text else "the top level"


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= MAX_VALUE_CHARS else text[: MAX_VALUE_CHARS - 5] + " ...}"


def _has_path(doc: object, path: Sequence[object]) -> bool:
    for part in path:
        if isinstance(doc, Mapping) and part in doc:
            doc = doc[part]
        elif isinstance(doc, list) and isinstance(part, int) and 0 <= part < len(doc):
            doc = doc[part]
        else:
            return False
    return True


def source_of(path: Sequence[object], sources: Sequence[tuple[str, object]]) -> str:
    """The last (highest-precedence) source whose document holds ``path``; else the first."""
    for name, doc in reversed(sources):
        if _has_path(doc, path):
            return name
    return sources[0][0]


def _known_keys(schema: Mapping) -> list[str]:
    return sorted(schema.get("properties", {}))


def _describe(error: jsonschema.ValidationError) -> list[tuple[list[object], str]]:
    """(path of the key concerned, what is wrong) for one schema error."""
    path = list(error.absolute_path)
    schema, instance = error.schema, error.instance
    if error.validator == "additionalProperties" and isinstance(instance, Mapping):
        known = _known_keys(schema)
        patterns = list(schema.get("patternProperties", {}))
        extra = [k for k in instance if k not in known and not any(re.search(p, str(k)) for p in patterns)]
        out = []
        for key in extra:
            hint = did_you_mean(key, known) or f" (known keys: {', '.join(known)})"
            out.append((path + [key], f"unknown key {key!r}{hint}"))
        return out
    if error.validator == "enum":
        return [(path, f"{_short(instance)} is not one of {list(error.validator_value)}"
                       f"{did_you_mean(instance, error.validator_value)}")]  # fmt: skip
    description = schema.get("description") if isinstance(schema, Mapping) else None
    if error.validator == "not":
        return [
            (path, f"{_short(instance)} is not allowed here" + (f" ({description})" if description else ""))
        ]
    if error.validator in ("oneOf", "anyOf"):
        if not isinstance(instance, Mapping) and "type" in schema:
            return []  # the type error says it
        forms = [" + ".join(f"`{k}`" for k in alt["required"]) for alt in error.validator_value
                 if isinstance(alt, Mapping) and alt.get("required")]  # fmt: skip
        if forms and isinstance(instance, Mapping):
            has = ", ".join(f"`{k}`" for k in instance) or "none"
            what = f"needs exactly one of {' or '.join(forms)}; it has {has}"
        else:
            best = jsonschema.exceptions.best_match(error.context).message if error.context else None
            what = best or f"{_short(instance)} does not have an allowed form"
        return [(path, f"{description}: {what}" if description else what)]
    message = error.message
    text = repr(instance)
    if len(text) > MAX_VALUE_CHARS:
        message = message.replace(text, _short(instance))
    if error.validator == "pattern" and description:
        message += f" ({description})"
    return [(path, message)]


def schema_problems(instance: object, schema: Mapping, sources: Sequence[tuple[str, object]]) -> list[str]:
    """One line per problem of ``instance`` against the JSON ``schema`` (draft 2020-12):
    ``"<file>: <key path>: <what is wrong>[; did you mean 'x'?]"``, sorted by key path.

    ``sources`` are (name, document) pairs in increasing precedence (config/config.yaml, a
    ``--configfile``, ``--config``); a line names the last one that holds the key concerned
    (for a missing key: its parent), else the first. An empty list: ``instance`` is valid.
    """
    validator = jsonschema.Draft202012Validator(schema)
    found = [item for error in validator.iter_errors(instance) for item in _describe(error)]
    lines: list[str] = []
    for path, what in sorted(found, key=lambda item: [str(part) for part in item[0]]):
        line = f"{source_of(path, sources)}: {key_path(path)}: {what}"
        if line not in lines:
            lines.append(line)
    if len(lines) > MAX_PROBLEMS:
        lines = lines[:MAX_PROBLEMS] + [f"... and {len(lines) - MAX_PROBLEMS} more"]
    return lines


def unknown_top_level_keys(doc: object, schema: Mapping) -> list[str]:
    """The top-level keys of ``doc`` that ``schema`` does not name, each with a "did you mean"
    for a near miss: ``["'frame' (did you mean 'frames'?)"]``. Extra keys may be allowed (a
    recorder writes more); a typo of a key the workflow reads is then silently ignored."""
    if not isinstance(doc, Mapping):
        return []
    known = _known_keys(schema)
    out = []
    for key in doc:
        if key not in known:
            hint = did_you_mean(key, known)
            out.append(f"{key!r}" + (f" ({hint[2:]})" if hint else ""))
    return out


# ---------------------------------------------------------------- failed jobs


_ERROR_BLOCK = re.compile(r"^Error in rule (?P<rule>\S+?):\s*$")
_BLOCK_FIELD = re.compile(r"^\s+(?P<key>\w+): (?P<value>.*)$")
_LOG_HINT = " (check log file(s) for error details)"
_EXCEPTION = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception|Exit|Interrupt|Warning)\b.*")


def failed_jobs(snakemake_log: str) -> list[dict[str, Any]]:
    """The failed jobs of a Snakemake run, from its log text (the ``Error in rule ...:`` blocks):
    dicts with ``rule``, ``wildcards`` (the text after ``wildcards:``, or "") and ``logs`` (the
    job's log files), in the order they failed, each job once."""
    jobs: list[dict[str, Any]] = []
    current: dict[str, Any] | None = None
    for line in snakemake_log.splitlines():
        head = _ERROR_BLOCK.match(line)
        if head:
            current = {"rule": head["rule"], "wildcards": "", "logs": []}
            jobs.append(current)
            continue
        field = _BLOCK_FIELD.match(line) if current is not None else None
        if field is None or current is None:  # (field is None whenever current is)
            current = None if not line.startswith(" ") else current
            continue
        if field["key"] == "wildcards":
            current["wildcards"] = field["value"].strip()
        elif field["key"] == "log":
            value = field["value"].replace(_LOG_HINT, "").strip()
            current["logs"] = [p.strip() for p in value.split(", ") if p.strip()]
    unique: list[dict[str, Any]] = []
    for job in jobs:
        if job not in unique:
            unique.append(job)
    return unique


def job_log_reason(text: str, max_lines: int = MAX_REASON_LINES) -> str:
    """The meaningful end of a job's log: the exception line (and its message's continuation
    lines) of the last Python traceback, else the last non-empty lines. At most ``max_lines``."""
    lines = [line.rstrip() for line in text.splitlines()]
    starts = [i for i, line in enumerate(lines) if line.startswith("Traceback (most recent call last)")]
    if starts:
        for i in range(starts[-1] + 1, len(lines)):
            if lines[i] and not lines[i].startswith((" ", "\t")):
                reason = [line for line in lines[i:] if line.strip()]
                break
        else:
            reason = []
    else:
        reason = []
    if not reason:
        named = [i for i, line in enumerate(lines) if _EXCEPTION.match(line)]
        tail = lines[named[-1] :] if named else lines
        reason = [line for line in tail if line.strip()][-TAIL_LINES:]
    if len(reason) > max_lines:
        reason = reason[: max_lines - 1] + [f"... ({len(reason) - max_lines + 1} more lines in the log)"]
    return "\n".join(reason)


def format_failed_jobs(snakemake_logs: str | Sequence[str]) -> str:
    """What the Snakefile's ``onerror`` prints: per failed job (from Snakemake's log files, as
    ``onerror`` receives them: one path in Snakemake 8, a list in 9) its rule, wildcards, log
    file and the reason at the end of that log. "" when no failed job is found."""
    paths = [snakemake_logs] if isinstance(snakemake_logs, str) else list(snakemake_logs or [])
    text = ""
    for path in paths:
        try:
            text += Path(path).read_text(errors="replace") + "\n"
        except OSError:
            continue
    jobs = failed_jobs(text)
    if not jobs:
        return ""
    out = [f"triaxtrack: {len(jobs)} job(s) failed; the reason at the end of each job's log:"]
    for job in jobs:
        where = f" ({job['wildcards']})" if job["wildcards"] else ""
        if not job["logs"]:
            out.append(f"  rule {job['rule']}{where}: no log file; see the error above")
            continue
        for log in job["logs"]:
            try:
                reason = job_log_reason(Path(log).read_text(errors="replace"))
            except OSError as err:
                reason = f"(cannot read the log: {err.strerror})"
            out.append(f"  rule {job['rule']}{where}, {log}:")
            out += [f"    {line}" for line in (reason or "(the log is empty)").splitlines()]
    return "\n".join(out)
