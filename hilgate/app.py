"""The application API's public name: ``from hilgate.app import Application`` (it lives in
:mod:`hilgate.core.application`; ``hilgate sim`` runs applications in virtual time
(:mod:`hilgate.sim.apps`), ``hilgate app`` as a process against a daemon (:mod:`hilgate.gli.app_runner`))."""

from .core.application import Application, Context, Message

__all__ = ["Application", "Context", "Message"]
