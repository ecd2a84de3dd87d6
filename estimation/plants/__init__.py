"""Ground-truth plants: simulators that return measured signals together with their truth."""
