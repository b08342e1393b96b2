"""Markers: ``pytest -m "not slow"`` runs the unit tests (engine, scenes, analysis; no process, no DDS).

Everything under ``integration/`` starts nodes as separate processes over DDS or writes and reads
bags through a writer process, and is marked ``slow`` here; a unit test that needs minutes is marked
``slow`` where it is written.
"""
from pathlib import Path

import pytest

INTEGRATION = Path(__file__).parent / "integration"


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: takes processes, DDS or minutes (deselect with -m 'not slow')")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if INTEGRATION in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.slow)
