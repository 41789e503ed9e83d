"""The OS processes of a run: started (forked, from the zygote, or exec), watched, restarted,
stopped by PID."""
