"""One router per concern: schedules, health probes, metrics."""
