"""Gait files: the YAML description of a crawler and its periodic actuation (docs/model.md §1).

    document     `load_gait` and `Gait`: reading, validating and editing a gait file
    signals      the T-periodic signals L_i(t) and mu_j(t)
    units        the ``units:`` block and the units of derived quantities
    docpaths     dotted paths into a gait document (``--sweep PATH=...``)
    yamlsafe     bounded, safe YAML reading
    schemacheck  the compiled check of crawlsim's JSON Schemas
    corpus       seeded random valid gaits
"""
