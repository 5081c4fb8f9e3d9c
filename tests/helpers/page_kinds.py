"""The example kinds of docs/architecture.md (a source, an output, a method), taken
from the page itself as one module's text, for the seams test and the plug-in test,
and the page's example of the plug-in's own test."""

from __future__ import annotations

import re

from .paths import ROOT

#: What the page's examples take as given.
PRELUDE = '''from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eskin_industrial.bus.source import Source
from eskin_industrial.seam import NodeLike, OpenContext
from eskin_industrial.detect.methods import UNUSED, Method, Score, batch_via_stream
from eskin_industrial.detect.scored import ScoredDetector
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.detect.state import GraspState
from eskin_industrial.frames import RawScan
from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.base import CliOption, OutputKind, Sink
from eskin_industrial.schema import in_range
'''

#: The registry lines the page shows (the tests register the kinds themselves).
REGISTRY_LINE = re.compile(r"^(SOURCES|SINKS|METHODS)\[.*$", flags=re.M)


def page_examples() -> str:
    """The Python blocks of docs/architecture.md, less their registry lines, as one module."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 3, "the page shows one source, one output and one method"
    return PRELUDE + "\n".join(REGISTRY_LINE.sub("", b) for b in blocks)


def page_plugin_test() -> str:
    """The plug-in's own test the page shows (the block that calls the conformance checks)."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    (block,) = [b for lang, b in re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M)
                if not lang and "eskin_industrial.testing" in b]
    return block
