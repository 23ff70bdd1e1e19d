"""Reports built from the product itself: the accuracy-cost trade-off of every solver knob."""
