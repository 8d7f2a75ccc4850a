"""The Foxglove live view: the WebSocket server and the foxglove_view node."""
