"""Settings every test shares: Hypothesis runs the same examples on every machine.

``make test`` (and plain ``pytest``) uses the ``vbn`` profile: derandomized (examples
drawn from a hash of each test, the same on every run), no example database, no
deadline (a loaded machine must not fail a property). A failure Hypothesis ever found is
kept beside its test as an ``@example``, so that it is tested on every run. To look for
new failures with fresh random examples: ``HYPOTHESIS_PROFILE=explore pytest -k ...``
(ten times the examples); add what it finds as an ``@example``.
"""
from __future__ import annotations

import os

from hypothesis import settings

# The fixtures every package's tests share (ros2_ws/test_support, on pytest's pythonpath):
# the DDS domain of the run, processes stopped at teardown, the session's room database.
pytest_plugins = ['vbn_fixtures']

settings.register_profile('vbn', derandomize=True, database=None, deadline=None,
                          print_blob=True)
settings.register_profile('explore', derandomize=False, database=None, deadline=None,
                          max_examples=1000, print_blob=True)
settings.load_profile(os.environ.get('HYPOTHESIS_PROFILE', 'vbn'))
