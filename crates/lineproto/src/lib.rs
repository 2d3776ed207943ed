//! lineproto: InfluxDB line protocol as Telegraf writes and reads it.
