"""Camera model, rigid transforms, support-plane fitting."""
