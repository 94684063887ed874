"""Recordings and viewers: the MCAP files a run writes and reads (mcap_io), their Foxglove
messages (foxglove) and the Rerun view (rerun_view).  Imports the layers below (util, math,
scenario, transport)."""
