"""Effects that a mill model is assembled from; one module per physical mechanism."""
