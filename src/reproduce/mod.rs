pub mod table2;
