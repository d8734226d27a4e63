//! The options table's unit tests.

use super::*;

fn settings(pairs: &[(&str, Setting)]) -> Result<(FilterOptions, Vec<String>)> {
    FilterOptions::from_settings(pairs.iter().map(|(k, v)| (k.to_string(), v.clone())))
}

#[test]
fn no_settings_are_the_command_lines_defaults() {
    let (o, given) = settings(&[]).unwrap();
    assert!(given.is_empty());
    assert_eq!(o.method, None);
    assert_eq!((o.tile, o.strip_rows, o.guides.as_str()), (256, 0, "auto"));
    assert!(o.knobs.is_empty());
    let (p, warnings) = o.params(&given).unwrap();
    assert_eq!(p, FilterParams::new(Method::EpGauss, 1));
    assert!(warnings.is_empty());
}

#[test]
fn settings_take_values_switches_and_lists() {
    let (o, given) = settings(&[
        ("tolerance", Setting::Value("0.1".into())),
        ("support-region", Setting::Value("0".into())),
        ("allow_lossy", Setting::Flag(true)),
        (
            "channel_rule",
            Setting::List(vec!["Z=drop".into(), "id=nearest".into()]),
        ),
        ("radius", Setting::Value("-1".into())),
    ])
    .unwrap();
    assert_eq!(o.knob("tolerance"), Some("0.1"));
    assert_eq!(o.knob("support_region"), Some("0"));
    assert!(o.allow_lossy);
    assert_eq!(o.channel_rule.len(), 2);
    assert_eq!(given, ["tolerance", "support_region", "radius"]);
    // A negative radius reaches the library's check, not the parser's.
    assert!(matches!(o.params(&given), Err(Error::Config(_))));
}

#[test]
fn unknown_and_malformed_settings_are_configuration_errors() {
    let e = settings(&[("tolerence", Setting::Value("0.1".into()))]).unwrap_err();
    assert!(
        e.to_string().contains("unknown setting \"tolerence\""),
        "{e}"
    );
    assert!(e.to_string().contains("tolerance"), "{e}");
    let e = settings(&[("tolerance", Setting::Value("x".into()))]).unwrap_err();
    assert!(
        matches!(e, Error::Config(_)) && e.to_string().contains("tolerance"),
        "{e}"
    );
    let e = settings(&[("tolerance", Setting::Flag(true))]).unwrap_err();
    assert!(e.to_string().contains("takes a value"), "{e}");
    let e = settings(&[("allow_lossy", Setting::Value("yes".into()))]).unwrap_err();
    assert!(e.to_string().contains("switch"), "{e}");
}

#[test]
fn options_the_method_ignores_are_warned_about() {
    let (o, given) = settings(&[
        ("method", Setting::Value("gauss".into())),
        ("tolerance", Setting::Value("0.1".into())),
    ])
    .unwrap();
    let (_, warnings) = o.params(&given).unwrap();
    assert_eq!(warnings, ["--tolerance has no effect with --method gauss"]);
}

/// The values an option lists for completions are values it takes, and
/// the knobs' lists (the binary's) are their parsers' names.
#[test]
fn every_listed_value_parses() {
    let listed: Vec<_> = OPTIONS.iter().filter(|d| !d.values.is_empty()).collect();
    assert!(listed.len() >= 7, "{}", listed.len());
    for d in listed {
        for v in d.values {
            settings(&[(d.name, Setting::Value(v.to_string()))])
                .unwrap_or_else(|e| panic!("--{} {v}: {e}", d.option()));
        }
    }
    for q in crate::filter::Quality::NAMES {
        assert!(crate::filter::Quality::parse(q).is_ok(), "{q}");
    }
    for g in crate::filter::ep_box::Guard::NAMES {
        assert!(crate::filter::ep_box::Guard::parse(g).is_ok(), "{g}");
    }
    for (m, name) in Method::ALL.iter().zip(Method::NAMES) {
        assert_eq!(m.name(), name);
    }
}

#[test]
fn one_table_serves_filter_and_restore() {
    // Restore's own settings are not filter's, and filter's not restore's.
    let named = |n: &str, v: &str| vec![(n.to_string(), Setting::Value(v.to_string()))];
    let e = FilterOptions::from_settings(named("scale", "16")).unwrap_err();
    assert!(e.to_string().contains("unknown setting \"scale\""), "{e}");
    let e = FilterOptions::for_restore(named("tolerance", "0.1")).unwrap_err();
    assert!(e.to_string().contains("restore's settings are"), "{e}");
    // The table's default scale is the library's.
    let o = FilterOptions::for_restore(Vec::new()).unwrap();
    assert_eq!(o.scale, crate::filter::restore::DEFAULT_SCALE);
    let o = FilterOptions::for_restore(named("keep-gain", "2")).unwrap();
    let files = (
        PathBuf::from("d.exr"),
        PathBuf::from("e.exr"),
        PathBuf::from("o.exr"),
    );
    let (job, _) = o.restore_job(files, None).unwrap();
    assert_eq!(
        (job.keep_gain, job.scale),
        (Some(2.0), crate::filter::restore::DEFAULT_SCALE)
    );
}
