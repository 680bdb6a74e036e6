"""pytest-benchmark suite (issue #7): ``make benchmark`` times it, ``make test`` runs each body once.

Files are named ``test_*.py`` so the default collection finds them; ``--benchmark-disable``
(pyproject ``addopts``) turns every benchmark into a single plain call.
"""

import pytest

from plant import PlantParams


@pytest.fixture(scope="session")
def params() -> PlantParams:
    """Table 2-1, the thesis scenario's plant."""
    return PlantParams()
