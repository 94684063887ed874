"""The zswarm world process: ground truth and sensors."""
