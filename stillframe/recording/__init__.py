"""Recording and playback over the node API: topics into a bag, and a bag back onto topics."""
