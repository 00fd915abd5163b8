"""Interactive 3-D view (placeholder)."""

def _cli(scene, host="127.0.0.1", port=8080):
    raise NotImplementedError
