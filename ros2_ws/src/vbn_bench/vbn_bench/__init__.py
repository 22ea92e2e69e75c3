"""vbn_bench: every benchmark, the demo and the offline evaluation; a robot installs none of it.

The decomposition benchmark of the thesis's Tables 8.2 to 8.4 (``decomposition/``), the
build's time and memory (``build.py``), class purity against a rendered scene's truth
(``purity.py``), the localizer over bags offline with its evaluation, the full-feature
baseline and the structure-based peer (``localization/``), and the commands that run them
(``cli/``: ``vbn localize``, ``demo`` and every ``bench-*``). Stands on every other
package of the project; the only one that may import matplotlib's plots, evo and pycolmap
for its own measurements.
"""
from __future__ import annotations

__all__: list[str] = []
