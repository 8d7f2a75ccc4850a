"""estimation_map: a map_server map built from a recording with known poses."""
