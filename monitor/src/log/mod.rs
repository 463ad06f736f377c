//! MCAP logs: message types, JSON schemas, a writer with reproducible output, and a streaming reader.
