"""Contact laws a tissue step can solve with its equilibrium: the contract between the contact layer,
which builds a law from its state, and the tissue layer, which solves it (:mod:`.plane`)."""
