//! The effect grammar and the families' parse, canonical form, words and
//! sameness.

use super::*;
use crate::features::Phase;

#[test]
fn a_thermal_effect_may_follow_several_channels() {
    let e = Effect::parse("thermal:target=ez,channel=housing+column,lag_s=600+0").unwrap();
    assert_eq!(
        e.spec.to_string(),
        "thermal:target=ez,channel=housing+column,lag_s=600+0"
    );
    let ch: Vec<(String, f64)> = e
        .features
        .iter()
        .map(|f| match f {
            Feature::Thermal { channel, lag_s, .. } => (channel.clone(), *lag_s),
            _ => panic!("{f:?}"),
        })
        .collect();
    assert_eq!(ch, vec![("housing".into(), 600.0), ("column".into(), 0.0)]);
    let e = Effect::parse("thermal:target=ex,channel=a+b,times=x,offset=1,lag_s=60").unwrap();
    assert_eq!(e.features.len(), 4);
    for bad in [
        "thermal:target=ez,channel=a+b,lag_s=1+2+3",
        "thermal:target=ez,channel=a+a",
        "thermal:target=ez,channel=a+",
        "thermal:target=ez,channel=a+b,lag_s=1+-2",
    ] {
        assert!(Effect::parse(bad).is_err(), "{bad}");
    }
}

#[test]
fn effect_parsing() {
    let e = Effect::parse("periodic:target=ey,axis=y,period_mm=5.08,harmonics=2").unwrap();
    assert_eq!(e.target(), 1);
    assert_eq!(e.features.len(), 4);
    assert_eq!(
        e.features[2],
        Feature::Periodic {
            axis: 1,
            period_mm: 5.08,
            harmonic: 2,
            phase: Phase::Sin
        }
    );
    let e = Effect::parse("thermal:target=ex,channel=bed,times=x").unwrap();
    assert_eq!(
        e.features,
        vec![Feature::Thermal {
            channel: "bed".into(),
            t_ref_c: 20.0,
            lag_s: 0.0,
            exp: [1, 0, 0]
        }]
    );
    assert_eq!(Effect::parse(&e.spec.to_string()).unwrap(), e);
    for bad in [
        "periodic",
        "periodic:target=ey,axis=q,period_mm=5",
        "periodic:target=ey,axis=y",
        "periodic:target=ey,axis=y,period_mm=-1",
        "periodic:target=ey,axis=y,period_mm=5,harmonics=9",
        "wobble:target=ex",
        "reversal:target=ex,axis=x,extra=1",
        "squareness:target=ex,axis=x",
        "drift:target=ex,target=ey",
    ] {
        let err = format!("{:#}", Effect::parse(bad).unwrap_err());
        assert!(err.contains(bad), "{err}");
    }
}

/// The messages a user reads for a bad `--add`, word for word (the
/// CLI snapshot and the docs show them).
#[test]
fn bad_add_strings_say_what_was_expected() {
    let msg = |s: &str| format!("{:#}", s.parse::<EffectSpec>().unwrap_err());
    // The list is the registry's (the CLI snapshot has today's words).
    assert_eq!(
        msg("wobble:target=ex"),
        format!(
            "bad effect `wobble:target=ex`: unknown effect family `wobble` (expected {})",
            Family::names()
        )
    );
    assert_eq!(or_list(&["a", "b", "c"]), "a, b or c");
    assert!(Family::names().starts_with("periodic, thermal, reversal, abbe, drift, squareness"));
    for (s, want) in [
        ("periodic", "bad effect `periodic`: expected `<family>:<key>=<value>,…`, e.g. `periodic:target=ey,axis=y,period_mm=5`"),
        ("reversal:target=ex,axis", "bad effect `reversal:target=ex,axis`: `axis`: expected key=value"),
        ("drift:target=ex,target=ey", "bad effect `drift:target=ex,target=ey`: key `target` given twice"),
        ("reversal:target=ex,axis=x,extra=1", "bad effect `reversal:target=ex,axis=x,extra=1`: unknown key `extra` for `reversal` (expected target, axis)"),
        ("abbe:times=x", "bad effect `abbe:times=x`: missing `target=`"),
        ("abbe:target=eq", "bad effect `abbe:target=eq`: `target=eq`: expected ex, ey or ez"),
        ("periodic:target=ey,axis=y,period_mm=x", "bad effect `periodic:target=ey,axis=y,period_mm=x`: `period_mm=x`: expected a number"),
        ("periodic:target=ey,axis=y,period_mm=inf", "bad effect `periodic:target=ey,axis=y,period_mm=inf`: `period_mm=inf`: expected a finite number"),
        ("drift:target=ex,order=4", "bad effect `drift:target=ex,order=4`: `order=4`: expected an integer 1..=3"),
        ("squareness:target=ey,axis=y", "bad effect `squareness:target=ey,axis=y`: squareness of y against itself: `axis` must differ from the target's axis"),
    ] {
        assert_eq!(msg(s), want);
    }
}

#[test]
fn specs_keep_the_string_as_written_and_type_its_parts() {
    for s in [
        "periodic:target=ey,axis=y,period_mm=5.08,harmonics=2",
        "thermal:target=ex,times=x,channel=bed,lag_s=600",
        "abbe:target=ez",
        "higher_order:target=ex,axis=y,degree=5",
    ] {
        let spec: EffectSpec = s.parse().unwrap();
        assert_eq!(spec.to_string(), s);
    }
    let t: EffectSpec = "thermal:target=ex, channel = bed ,times=x".parse().unwrap();
    assert_eq!(t.family(), Family::Thermal);
    assert_eq!(t.target(), Target::Ex);
    assert_eq!(t.channel(), Some("bed"));
    assert_eq!(t.times(), Some(Axis::X));
    assert_eq!(t.axis(), None);
    assert_eq!(t.to_string(), "thermal:target=ex,channel=bed,times=x");
    let e = "wobble:target=ex".parse::<EffectSpec>().unwrap_err();
    assert!(
        format!("{e:#}").contains("unknown effect family `wobble`"),
        "{e:#}"
    );
    assert_eq!(
        "higher_order".parse::<Family>().unwrap(),
        Family::HigherOrder
    );
    assert_eq!(Family::HigherOrder.to_string(), "higher_order");
    assert_eq!(
        serde_json::to_string(&Family::HigherOrder).unwrap(),
        "\"higher_order\""
    );
    assert_eq!("y".parse::<Axis>().unwrap().index(), 1);
    assert_eq!(Target::from_index(2), Some(Target::Ez));
    assert_eq!(Target::from_index(3), None);
    let e = "q".parse::<Axis>().unwrap_err().to_string();
    assert_eq!(e, "`q`: expected x, y or z");
    assert_eq!("ez".parse::<Target>().unwrap().to_string(), "ez");
}

/// A spec the search builds from types is the string that parses back
/// to it, in each family's canonical order.
#[test]
fn specs_built_from_types_are_written_in_canonical_order_and_parse_back() {
    let built = [
        EffectSpec::new(
            Target::Ey,
            periodic::Periodic {
                axis: Axis::Y,
                period_mm: 5.08006,
                harmonics: 2,
            },
        ),
        EffectSpec::new(
            Target::Ex,
            thermal::Thermal::new("bed", Some(Axis::X), vec![7200.0]),
        ),
        EffectSpec::new(
            Target::Ez,
            thermal::Thermal::new("housing+column", None, vec![600.0, 0.0]),
        ),
        EffectSpec::new(Target::Ez, thermal::Thermal::new("bed", None, vec![0.0])),
        EffectSpec::new(Target::Ex, reversal::Reversal { axis: Axis::X }),
        EffectSpec::new(
            Target::Ey,
            abbe::Abbe {
                times: Some(Axis::X),
            },
        ),
        EffectSpec::new(Target::Ey, drift::Drift { order: 3 }),
        EffectSpec::new(Target::Ey, drift::Drift { order: 1 }),
        EffectSpec::new(Target::Ex, squareness::Squareness { axis: Axis::Y }),
        EffectSpec::new(
            Target::Ey,
            higher_order::HigherOrder {
                axis: Axis::Y,
                degree: 5,
            },
        ),
    ];
    let want = [
        "periodic:target=ey,axis=y,period_mm=5.08006,harmonics=2",
        "thermal:target=ex,channel=bed,times=x,offset=1,lag_s=7200",
        "thermal:target=ez,channel=housing+column,lag_s=600+0",
        "thermal:target=ez,channel=bed",
        "reversal:target=ex,axis=x",
        "abbe:target=ey,times=x",
        "drift:target=ey,order=3",
        "drift:target=ey",
        "squareness:target=ex,axis=y",
        "higher_order:target=ey,axis=y,degree=5",
    ];
    for (b, w) in built.iter().zip(want) {
        assert_eq!(b.to_string(), w);
        let back: EffectSpec = w.parse().unwrap();
        assert_eq!(&back, b);
        assert_eq!(back.params(), b.params(), "{w}");
    }
}

#[test]
fn same_effect_compares_the_typed_parts() {
    let s = |a: &str| a.parse::<EffectSpec>().unwrap();
    // Spaces around keys and values, key order: the same effect.
    assert!(s("thermal:target=ex,channel=bed,lag_s=3600")
        .same_effect(&s("thermal: lag_s = 600 , channel=bed,target=ex")));
    // Another channel, target or `times`: another effect.
    assert!(!s("thermal:target=ex,channel=bed,lag_s=0")
        .same_effect(&s("thermal:target=ex,channel=spindle,lag_s=0")));
    assert!(s("thermal:target=ex,channel=bed,times=x,lag_s=600")
        .same_effect(&s("thermal:target=ex,times=x,channel=bed")));
    assert!(!s("abbe:target=ex,times=y").same_effect(&s("abbe:target=ex")));
    // Periods within 10 % are one lead re-found; farther, two effects.
    let p = |mm: &str| s(&format!("periodic:target=ey,axis=y,period_mm={mm}"));
    assert!(p("5").same_effect(&p("5.4")));
    assert!(!p("5").same_effect(&p("10")));
}

#[test]
fn the_words_of_each_family() {
    let w = |a: &str| a.parse::<EffectSpec>().unwrap().describe();
    assert_eq!(
        w("periodic:target=ey,axis=y,period_mm=5"),
        "a periodic error of ey along y (lead screw or scale pitch)"
    );
    assert_eq!(
        w("thermal:target=ex,channel=bed,times=x,offset=1"),
        "thermal growth of ex with the bed temperature, growing along x"
    );
    assert_eq!(
        w("thermal:target=ez,channel=spindle_housing+column,lag_s=600+0"),
        "thermal growth of ez with the spindle housing and column temperature"
    );
    assert_eq!(
        w("abbe:target=ey,times=x"),
        "an Abbe error of ey (a tilt times the tool length) along x"
    );
    assert_eq!(w("drift:target=ex,order=3"), "a drift of ex with time");
    assert_eq!(
        w("higher_order:target=ex,axis=y,degree=5"),
        "a smooth shape of ex along y the seed cannot follow (higher order, not a named physical effect)"
    );
}

#[test]
fn plan_options_may_be_flags_effects_may_not() {
    let kv = Pairs::parse_with_flags("x=400, bidir ,runs=3,").unwrap();
    assert!(kv.flag("bidir").unwrap());
    assert_eq!(kv.f64("x").unwrap(), Some(400.0));
    let e = kv.finish("x, bidir, runs").unwrap_err().to_string();
    assert_eq!(e, "unknown key `runs` (expected x, bidir, runs)");
    assert_eq!(kv.usize("runs").unwrap(), Some(3));
    kv.finish("x, bidir, runs").unwrap();
    let e = Pairs::parse("x=1,bidir").unwrap_err().to_string();
    assert_eq!(e, "`bidir`: expected key=value");
    let e = Pairs::parse_with_flags("bidir,bidir=0")
        .unwrap_err()
        .to_string();
    assert_eq!(e, "key `bidir` given twice");
    let kv = Pairs::parse_with_flags("new_session").unwrap();
    assert_eq!(
        kv.get("new_session").unwrap_err().to_string(),
        "`new_session`: expected `new_session=<value>`"
    );
}
