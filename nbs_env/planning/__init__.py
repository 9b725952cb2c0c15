"""Planning: traversability, next valid positions (NVPs) and paths, and the NBS gain."""
