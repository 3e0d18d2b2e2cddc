"""Results: what scoring produces and every output reads, as typed objects, with the one JSON
encoder and decoder (:mod:`.codec`). Imports the core and nothing that reads or writes files."""
