"""Weather and imperfect sensing (issue 53): the processes behind `[wind]`, `[sensing]`
and `[vehicle] gps_*`, shared by the networked simulator and lock-step."""
