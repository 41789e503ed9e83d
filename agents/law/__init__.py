"""Control laws: the interface a law implements (agents.law.interface) and the shipped ones."""
