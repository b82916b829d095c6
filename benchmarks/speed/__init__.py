"""How fast: batches, image files, time budgets, tracking, detection."""
