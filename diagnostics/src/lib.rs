//! fdd-diagnostics: change detectors on innovations, fault isolation and the OBD-style event
//! memory. Empty until the diagnostics issue builds it (see shared/DESIGN.md).
