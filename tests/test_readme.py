"""The README's examples run as written."""
import doctest
import logging
from pathlib import Path

import torchrl  # noqa: F401  (it sets its logger's level on import: import it before quieting it)

README = Path(__file__).parents[1] / "README.md"


def test_the_readme_sampler_example_runs_as_written():
    # TorchRL logs storage initialisation to stdout, which doctest would read as output.
    torchrl_logger = logging.getLogger("torchrl")
    level = torchrl_logger.level
    torchrl_logger.setLevel(logging.WARNING)
    try:
        failures, tried = doctest.testfile(str(README), module_relative=False, optionflags=doctest.ELLIPSIS)
    finally:
        torchrl_logger.setLevel(level)
    assert tried >= 10 and failures == 0
