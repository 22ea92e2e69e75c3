"""The localizer's benchmark and evaluation (as vbn_bench.decomposition is the decomposition's).

:mod:`.pose_bags` (run bags in, pose bags out), :mod:`.offline` (the core over a
recorded run, timed), :mod:`.evaluation` (accuracy, availability, switching, latency,
recovery; evo's APE beside ours), :mod:`.baseline` (localization against every
feature of the exploration, the comparison a user would make), :mod:`.plots`
(trajectories over the regions), :mod:`.report` (the table of ``vbn bench-localize``),
:mod:`.conditions` (the lens bags and conditions) and
:mod:`.demo` (the evaluation of ``vbn demo``'s recording). The ``vbn`` commands
``localize``, ``bench-localize`` and ``demo`` are thin layers over them.
"""
