"""The GLI client library's public name: ``from hilgate.client import Link`` (it lives in
:mod:`hilgate.gli.socket_client`)."""

from .gli.socket_client import GliError, Link, Message

__all__ = ["Link", "Message", "GliError"]
