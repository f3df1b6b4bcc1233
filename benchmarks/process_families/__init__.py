"""The families that measure what a run's processes cost beside its work: starting them
(``process_start``: forked from the fork server or exec'd) and what they leave in /dev/shm
(``leftovers``)."""
