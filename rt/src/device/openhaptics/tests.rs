use super::*;

#[test]
fn default_config_is_valid_and_each_rule_names_its_field() {
    assert_eq!(OpenHapticsConfig::default().validate(), Ok(()));
    let bad = [
        (
            OpenHapticsConfig {
                library: Some(PathBuf::new()),
                ..Default::default()
            },
            "library",
        ),
        (
            OpenHapticsConfig {
                device_name: Some(String::new()),
                ..Default::default()
            },
            "device_name",
        ),
        (
            OpenHapticsConfig {
                device_name: Some("a\0b".into()),
                ..Default::default()
            },
            "device_name",
        ),
        (
            OpenHapticsConfig {
                scheduler_rate_hz: 600,
                ..Default::default()
            },
            "scheduler_rate_hz",
        ),
        (
            OpenHapticsConfig {
                stall_ms: 0.5,
                ..Default::default()
            },
            "stall_ms",
        ),
        (
            OpenHapticsConfig {
                stall_ms: f64::NAN,
                ..Default::default()
            },
            "stall_ms",
        ),
    ];
    for (c, field) in bad {
        assert_eq!(c.validate().expect_err(field).field, field);
    }
}

#[test]
fn a_missing_library_is_one_error_naming_the_file_and_the_field() {
    let c = OpenHapticsConfig {
        library: Some(PathBuf::from("/nonexistent/coop/libHD.so")),
        ..Default::default()
    };
    let e = OpenHapticsDevice::open(&c).expect_err("no such file");
    let msg = e.to_string();
    assert!(
        matches!(e, OpenHapticsError::LibraryMissing { .. }),
        "{msg}"
    );
    assert!(msg.contains("/nonexistent/coop/libHD.so"), "{msg}");
    assert!(msg.contains("device.openhaptics.library"), "{msg}");
    let p = probe(&c);
    assert!(
        p.built_in && p.devices.is_empty() && p.status.contains("not found"),
        "{}",
        p.status
    );
}
