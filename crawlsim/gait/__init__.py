"""Gait files: the YAML description of a crawler and its periodic actuation (docs/model.md §1).

document            `load_gait`: reading a file, dispatching on its kind, listing its errors
crawler_spec        `Gait`: the crawler's schema, its semantic checks
crawler_limits      the limits of double precision on stiffness and stress scale
loads               the ``loads:`` block: forces and slopes, the shifted thresholds (§6)
uniqueness          the uniqueness condition, decided exactly, every violating subset listed
uniqueness_advice   what to change when the friction violates the uniqueness condition
process_spec        `ProcessSpec`: a generic sweeping process's schema and checks
settings            the ``simulation:`` settings and the bounds every document shares
validation          a plain copy, the structure check and the error collection of a document
signals             the T-periodic signals L_i(t) and mu_j(t)
schemaerrors        schema and finiteness checks with errors naming the key path
schemacheck         the compiled check of crawlsim's JSON Schemas
units               the ``units:`` block and the units of derived quantities
docpaths            dotted paths into a gait document (``--sweep PATH=...``)
yamlsafe            bounded, safe YAML reading
corpus              seeded random valid gaits
"""
