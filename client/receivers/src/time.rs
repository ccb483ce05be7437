//! UTC calendar arithmetic without a date library: receivers give civil dates and
//! times of day, the wire wants ns since the Unix epoch.

/// Nanoseconds per day.
pub const DAY_NS: u64 = 86_400 * 1_000_000_000;

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's
/// `days_from_civil`). `None` for impossible dates (month 13, 31 April, ...).
pub fn days_from_civil(year: i64, month: u32, day: u32) -> Option<i64> {
    if !(1..=12).contains(&month) || day < 1 || day > days_in_month(year, month) {
        return None;
    }
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = i64::from((month + 9) % 12);
    let doy = (153 * mp + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some(era * 146_097 + doe - 719_468)
}

/// The civil date `(year, month, day)` of a day count since 1970-01-01; the inverse
/// of [`days_from_civil`].
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

fn days_in_month(year: i64, month: u32) -> u32 {
    match month {
        2 if (year % 4 == 0 && year % 100 != 0) || year % 400 == 0 => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// ns since the Unix epoch of a day count plus ns into that day; `None` before 1970
/// or on overflow. `ns_of_day` may be negative or exceed a day (u-blox's signed
/// `nano` correction, a leap second).
pub fn unix_ns(days: i64, ns_of_day: i64) -> Option<u64> {
    let total = i128::from(days) * i128::from(DAY_NS) + i128::from(ns_of_day);
    u64::try_from(total).ok()
}

/// ns since midnight of `hh:mm:ss` plus `nanos` (signed), validating the ranges a
/// receiver may send (second 60 is a leap second).
pub fn ns_of_day(hour: u32, min: u32, sec: u32, nanos: i64) -> Option<i64> {
    if hour > 23 || min > 59 || sec > 60 {
        return None;
    }
    let secs = i64::from(hour * 3600 + min * 60 + sec);
    Some(secs * 1_000_000_000 + nanos)
}

/// Parses a run of ASCII digits as an unsigned number; `None` if empty or not all
/// digits.
pub fn digits(s: &[u8]) -> Option<u32> {
    if s.is_empty() || s.len() > 9 || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(s.iter().fold(0, |n, &d| n * 10 + u32::from(d - b'0')))
}

/// A fraction of a second written as the digits after the decimal point, in ns.
/// Digits past the ninth are ignored (receivers give at most three).
pub fn fraction_ns(s: &[u8]) -> Option<i64> {
    if !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let mut ns = 0i64;
    for i in 0..9 {
        ns = ns * 10 + s.get(i).map_or(0, |&d| i64::from(d - b'0'));
    }
    Some(ns)
}

/// [`ns_of_day`] of a time written in digits: hour, minute and second fields and the
/// digits after the decimal point (empty for none). NMEA and gpsd differ only in where
/// the fields stand.
fn written_ns_of_day(hour: &[u8], min: &[u8], sec: &[u8], frac: &[u8]) -> Option<i64> {
    ns_of_day(
        digits(hour)?,
        digits(min)?,
        digits(sec)?,
        fraction_ns(frac)?,
    )
}

/// NMEA time of day `hhmmss` or `hhmmss.sss` → ns since midnight.
pub fn parse_hhmmss(field: &[u8]) -> Option<u64> {
    let (whole, frac) = match field.iter().position(|&b| b == b'.') {
        Some(dot) => (&field[..dot], &field[dot + 1..]),
        None => (field, &[][..]),
    };
    if whole.len() != 6 {
        return None;
    }
    let ns = written_ns_of_day(&whole[0..2], &whole[2..4], &whole[4..6], frac)?;
    u64::try_from(ns).ok()
}

/// NMEA date `ddmmyy` → days since 1970. Two-digit years 80–99 are 1980–1999,
/// 00–79 are 2000–2079 (GPS time starts in 1980).
pub fn parse_ddmmyy(field: &[u8]) -> Option<i64> {
    if field.len() != 6 {
        return None;
    }
    let yy = i64::from(digits(&field[4..6])?);
    let year = if yy >= 80 { 1900 + yy } else { 2000 + yy };
    days_from_civil(year, digits(&field[2..4])?, digits(&field[0..2])?)
}

/// gpsd's ISO 8601 time `2024-01-30T15:31:52.100Z` → ns since the Unix epoch.
pub fn parse_iso8601(s: &str) -> Option<u64> {
    let b = s.as_bytes();
    if b.len() < 20 || b[4] != b'-' || b[7] != b'-' || b[10] != b'T' {
        return None;
    }
    if b[13] != b':' || b[16] != b':' || b.last() != Some(&b'Z') {
        return None;
    }
    let frac = match b[19] {
        b'Z' if b.len() == 20 => &[][..],
        b'.' => &b[20..b.len() - 1],
        _ => return None,
    };
    let days = days_from_civil(
        i64::from(digits(&b[0..4])?),
        digits(&b[5..7])?,
        digits(&b[8..10])?,
    )?;
    let ns = written_ns_of_day(&b[11..13], &b[14..16], &b[17..19], frac)?;
    unix_ns(days, ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_round_trip_and_known_days() {
        assert_eq!(days_from_civil(1970, 1, 1), Some(0));
        assert_eq!(days_from_civil(2000, 3, 1), Some(11_017));
        assert_eq!(days_from_civil(2024, 2, 29), Some(19_782));
        assert_eq!(days_from_civil(2023, 2, 29), None);
        assert_eq!(days_from_civil(2023, 13, 1), None);
        for d in (-800_000..800_000).step_by(997) {
            let (y, m, day) = civil_from_days(d);
            assert_eq!(days_from_civil(y, m, day), Some(d), "{y}-{m}-{day}");
        }
    }

    #[test]
    fn nmea_and_iso_times() {
        assert_eq!(parse_hhmmss(b"000000"), Some(0));
        assert_eq!(parse_hhmmss(b"123456.78"), Some(45_296_780_000_000));
        assert_eq!(parse_hhmmss(b"246000"), None);
        assert_eq!(parse_hhmmss(b"12345"), None);
        assert_eq!(parse_hhmmss(b"1234a6"), None);
        assert_eq!(parse_ddmmyy(b"091209"), days_from_civil(2009, 12, 9));
        assert_eq!(parse_ddmmyy(b"010180"), days_from_civil(1980, 1, 1));
        // 2024-01-30T15:31:52.100Z, checked with `date -u -d ... +%s%N`.
        assert_eq!(
            parse_iso8601("2024-01-30T15:31:52.100Z"),
            Some(1_706_628_712_100_000_000)
        );
        assert_eq!(
            parse_iso8601("2024-01-30T15:31:52Z"),
            Some(1_706_628_712_000_000_000)
        );
        assert_eq!(parse_iso8601("2024-01-30 15:31:52Z"), None);
        assert_eq!(parse_iso8601("2024-01-30T15:31:52.1"), None);
    }

    #[test]
    fn signed_nanos_and_range() {
        assert_eq!(unix_ns(1, -1), Some(DAY_NS - 1));
        assert_eq!(unix_ns(0, -1), None);
        assert_eq!(ns_of_day(23, 59, 60, 0), Some(86_400_000_000_000));
        assert_eq!(ns_of_day(24, 0, 0, 0), None);
    }
}
