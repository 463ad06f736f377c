pub mod intake;
pub mod table2;
pub mod turbo;
pub mod wheel;
