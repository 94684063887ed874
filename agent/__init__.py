"""The zswarm agent process: runtime loop and the pure algorithms it steps."""
