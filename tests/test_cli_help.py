"""The command-line help is a reference of its own: every option that has a default says it."""

from __future__ import annotations

import argparse

from hubsgo_ppl.cli import build_parser


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_option_with_a_default_names_it_in_its_help():
    missing = []
    for name, parser in _commands().items():
        for action in parser._actions:
            if not action.option_strings or isinstance(action, argparse._HelpAction):
                continue
            if action.default in (None, False, argparse.SUPPRESS) or action.required:
                continue
            if "default" not in (action.help or ""):
                missing.append(f"{name} {action.option_strings[0]}")
    assert not missing, missing

