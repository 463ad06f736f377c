//! fdd-monitor: the runtime a host embeds (signal table, scheduler, monitors, MCAP logs).
//! Empty until the runtime issue builds it (see shared/DESIGN.md).
