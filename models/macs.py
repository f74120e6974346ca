"""The MAC protocols a scene can name; user-defined ones are loaded by ``package.module:ClassName``."""

from __future__ import annotations

from .aloha import Aloha
from .csaloha import CsAloha
from .mac import Mac, NoMac
from .sfama import SFama

REGISTRY: dict[str, type[Mac]] = {"none": NoMac, "aloha": Aloha, "cs-aloha": CsAloha, "s-fama": SFama}
