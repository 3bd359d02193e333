"""Everything that knows a file format: log readers, writers, map_server, Parquet, TUM, manifests."""
