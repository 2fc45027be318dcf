"""The argument parser class of ``dv2s`` and the option groups several commands share."""

from __future__ import annotations

import argparse
import difflib
from typing import Callable, List

from dv2s_gym.cli.backend_options import dra_option
from dv2s_gym.pipeline.prompts import CAMERA_VIEWPOINTS

__all__ = ["Parser", "bank_command", "bank_option", "llm_options", "video_options"]


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line in the words of the (sub)command the user typed.

    argparse prints the whole usage block before a usage error and reports an unknown option of a
    subcommand as the top-level command's; here the subcommand that received it names it, with the
    closest option it has (only a really close one) and where its help is; an option of other
    subcommands (after :meth:`index_options`) is named as theirs.
    """

    CLOSE = 0.75
    """How alike (difflib's ratio) a mistyped option and an option of the command must be to be suggested."""

    _option_owners: dict = {}

    def index_options(self) -> None:
        """Tell every parser of the tree which (sub)commands take each option, for :meth:`_unrecognized`."""
        owners: dict = {}
        parsers = list(self._tree())
        for parser in parsers:
            for flag in parser._option_string_actions:
                if flag.startswith("--") and flag != "--help":
                    owners.setdefault(flag, []).append(parser.prog)
        for parser in parsers:
            parser._option_owners = owners

    def commands(self) -> dict:
        """This parser's subcommands, name -> parser."""
        return {name: child for action in self._actions if isinstance(action, argparse._SubParsersAction)
                for name, child in action.choices.items()}

    def _tree(self):
        yield self
        seen = set()
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for child in action.choices.values():
                    if id(child) not in seen and isinstance(child, Parser):  # aliases share a parser
                        seen.add(id(child))
                        yield from child._tree()

    def error(self, message: str):  # argparse's hook; never returns
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")

    def parse_known_args(self, args=None, namespace=None):
        leaf = not any(isinstance(action, argparse._SubParsersAction) for action in self._actions)
        if leaf and args is not None:  # a mistyped option is named before "--policy is required" hides it
            unknown = [token for token in args if token.startswith("--") and token != "--"
                       and not any(flag.startswith(token.split("=", 1)[0]) for flag in self._option_string_actions)]
            if unknown:
                self.error(self._unrecognized(unknown))
        namespace, extras = super().parse_known_args(args, namespace)
        if extras and leaf:
            self.error(self._unrecognized(extras))
        return namespace, extras

    def _check_value(self, action: argparse.Action, value) -> None:  # argparse's hook for ``choices``
        try:
            super()._check_value(action, value)
        except argparse.ArgumentError as error:
            close = difflib.get_close_matches(str(value), [str(choice) for choice in action.choices], n=1)
            if not close:
                raise
            raise argparse.ArgumentError(action, f"{error.message}; did you mean {close[0]!r}?") from None

    def _unrecognized(self, extras: List[str]) -> str:
        message = f"unrecognized arguments: {' '.join(extras)}"
        flags = [flag.split("=", 1)[0] for flag in extras if flag.startswith("-")]
        if not flags:
            return message
        close = difflib.get_close_matches(flags[0], list(self._option_string_actions), n=1, cutoff=self.CLOSE)
        if close:
            message += f"; did you mean {close[0]}?"
        owners = [prog for prog in self._option_owners.get(flags[0], []) if prog != self.prog]
        if owners:
            named = ", ".join(f"`{prog}`" + (" (before the command)" if " " not in prog else "")
                              for prog in owners[:4])
            more = f" and {len(owners) - 4} more" if len(owners) > 4 else ""
            message += f"; `{flags[0]}` is an option of {named}{more}, not of `{self.prog}`"
        return message


def bank_option(p: argparse.ArgumentParser) -> None:
    """``--bank`` on a subcommand (the top-level parser has its own), and the declaration that the command reads
    a bank (``reads_bank``): ``dv2s --bank DIR`` before any other command is refused, never ignored."""
    # SUPPRESS: given at several levels, the one the user wrote wins; not given, the top level's None stays
    p.add_argument("--bank", default=argparse.SUPPRESS, help="bank folder (default: the bank shipped with dv2s-gym)")
    p.set_defaults(reads_bank=True)


def bank_command(bank_sub, name: str, help_text: str, func: Callable[[argparse.Namespace], int]):
    """A ``dv2s bank`` subcommand with ``--bank`` and ``--json``, running ``func``."""
    p = bank_sub.add_parser(name, help=help_text, description=help_text)
    bank_option(p)
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.set_defaults(func=func)
    return p


def llm_options(p: argparse.ArgumentParser) -> None:
    """The settings of the model endpoint a backend calls (``openai``, or a plug-in's registered with
    ``reads_model``), in their own group of ``--help``; given with backends that call no model they are refused
    (:func:`~dv2s_gym.cli.inputs.llm_config`)."""
    group = p.add_argument_group("model endpoint", "read only by backends that call a model (--dra openai, "
                                                   "--sg openai, or a plug-in's)")
    group.add_argument("--base-url", help="OpenAI-compatible endpoint (default: $DV2S_LLM_BASE_URL)")
    group.add_argument("--model", help="model name (default: $DV2S_LLM_MODEL)")
    group.add_argument("--api-key", help="API key (default: $OPENAI_API_KEY)")


def video_options(p: argparse.ArgumentParser) -> None:
    """How a video is described: the Driving Record Analyzer, the camera, a question."""
    dra_option(p, help="Driving Record Analyzer: bev (offline, bird's-eye renders) or openai (any VLM endpoint)")
    cameras = sorted(CAMERA_VIEWPOINTS, key=lambda camera: camera != "bev")  # the default first
    p.add_argument("--camera", choices=cameras, default="bev", help="camera viewpoint")
    p.add_argument("--question", help='video-specific question, e.g. "Why did the ego vehicle brake?"')
