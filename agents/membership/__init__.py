"""Who is in the swarm: liveliness tokens, the members held, the ring they form, and its
accuracy."""
