"""Maps, scenarios and runs from and to other formats, one module per format: ``commonroad``
(import of CommonRoad XML scenarios), ``commonroad_export`` (runs as CommonRoad solutions and
scenarios), ``output`` (how every importer writes its map and scenario), ``codes`` (the
``YML44x`` findings all of them report). The format's own package is an optional extra imported
only inside these modules' functions (docs/architecture.md, "Interoperability")."""
