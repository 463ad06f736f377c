pub mod intake;
pub mod table2;
