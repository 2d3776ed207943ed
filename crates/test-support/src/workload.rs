//! The benchmark records shared by the criterion benches of crates/lineproto and of the plugin
//! (its codec, binding and record-path benches): a P2-shaped robot line (two speeds, one a
//! string) and a full robot message with a 360-beam scan, and a line's fields in the random
//! order Telegraf writes them (Go map order).

/// The P2 record.
pub const P2_LINE: &str = "mqtt_consumer,host=turtlebot3,topic=tessla actualSpeed=\"0.0188\",expectedSpeed=0.015 1719231000123456789\n";

/// A robot message with speeds and 360 lidar beams (deterministic, varied ranges like a real
/// scan: 0.12 .. 3.5 m), fields sorted.
pub fn lidar_line() -> String {
    let mut s = String::from(
        "mqtt_consumer,host=turtlebot3,topic=tessla actualAngular=0.0002,actualSpeed=\"0.0188\",expectedAngular=0,expectedSpeed=0.015",
    );
    for i in 0..360 {
        let r = 0.12 + f64::from((i * 7919) % 3380) / 1000.0;
        s.push_str(&format!(",lidar_{i}={r}"));
    }
    s.push_str(" 1719231000123456789\n");
    s
}

/// `line` with its fields in a fixed pseudo-random order, as Telegraf writes them.
pub fn unordered(line: &str) -> String {
    let (head, rest) = line.split_once(' ').unwrap_or_default();
    let (fields, ts) = rest.rsplit_once(' ').unwrap_or_default();
    let mut fields: Vec<&str> = fields.split(',').collect();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x2545_f491);
    for i in (1..fields.len()).rev() {
        let seed = rand::RngCore::next_u64(&mut rng);
        fields.swap(i, (seed % (i as u64 + 1)) as usize);
    }
    format!("{head} {} {ts}", fields.join(","))
}
