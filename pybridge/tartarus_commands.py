"""Tartarus-style agent commands of a :class:`dfrl.pybridge.Bridge`, with bound arguments.

Links are ``(Ip, Port)`` tuples; names and handlers given as ``str`` are atoms. The class is
a mixin: it needs the node's ``_must`` (call once, raise on failure) and ``_check_open``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from dfrl.pybridge.terms import Atom, Var, atom_or_self

__all__ = ["TartarusCommands"]


class TartarusCommands:
    """The platform's Tartarus API (``create_mobile_agent/4``, ``move_agent/2``, ...)."""

    def _must(self, name: str, *args: Any, module: str | None = None) -> dict[str, Any]:
        raise NotImplementedError

    def _check_open(self) -> None:
        raise NotImplementedError

    @staticmethod
    def _link(link: Sequence[Any]) -> tuple[Any, Any]:
        ip, port = link
        return (atom_or_self(ip), int(port))

    def create_mobile_agent(
        self, name: str | None, link: Sequence[Any], handler: str, tokens: Iterable[int] = ()
    ) -> Atom:
        """``create_mobile_agent(?Name, (Ip,Port), Handler, Tokens)``; returns the agent name."""
        self._check_open()
        name_arg: Any = Var("Name") if name is None else Atom(name)
        sol = self._must(
            "create_mobile_agent", name_arg, self._link(link), Atom(handler), list(tokens)
        )
        return Atom(sol["Name"]) if name is None else Atom(name)

    def create_static_agent(
        self, name: str | None, link: Sequence[Any], handler: str, tokens: Iterable[int] = ()
    ) -> Atom:
        """``create_static_agent(?Name, (Ip,Port), Handler, Tokens)``: an agent that never moves."""
        self._check_open()
        name_arg: Any = Var("Name") if name is None else Atom(name)
        sol = self._must(
            "create_static_agent", name_arg, self._link(link), Atom(handler), list(tokens)
        )
        return Atom(sol["Name"]) if name is None else Atom(name)

    def execute_agent(
        self, name: str, link: Sequence[Any], handler: str, event: Any = None
    ) -> None:
        """``execute_agent(Name, (Ip,Port), Handler)``, or ``execute_agent/4`` with a start
        ``event`` other than ``main``."""
        self._check_open()
        if event is None:
            self._must("execute_agent", Atom(name), self._link(link), Atom(handler))
        else:
            self._must(
                "execute_agent", Atom(name), self._link(link), Atom(handler), atom_or_self(event)
            )

    def move_agent(self, name: str, link: Sequence[Any]) -> None:
        """``move_agent(Name, (Ip,Port))``."""
        self._check_open()
        self._must("move_agent", Atom(name), self._link(link))

    def purge_agent(self, name: str) -> None:
        """``purge_agent(Name)``."""
        self._check_open()
        self._must("purge_agent", Atom(name))

    def list_agents(self) -> list[Any]:
        """``list_agents(List)``: the agents on this platform."""
        self._check_open()
        return list(self._must("list_agents", Var("L"))["L"])

    def assert_file_to_tartarus(self, path: str | Path) -> None:
        """``assert_file_to_tartarus(File)``: load agent code into the running platform."""
        self._check_open()
        self._must("assert_file_to_tartarus", Atom(str(path)))

    def add_payload(self, name: str, predicates: Iterable[tuple[str, int]]) -> None:
        """``add_payload(Name, [(Pred,Arity), ...])``."""
        self._check_open()
        self._must("add_payload", Atom(name), [(Atom(p), int(a)) for p, a in predicates])

    def post_agent(self, target: str, link: Sequence[Any], args: Sequence[Any]) -> None:
        """``post_agent(Target, (Ip,Port), [Handler, Agent, Link | Args])``; ``args`` are
        converted as described in :mod:`dfrl.pybridge.terms`."""
        self._check_open()
        self._must("post_agent", Atom(target), self._link(link), list(args))
