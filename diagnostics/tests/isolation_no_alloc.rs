//! Isolation runs every step of a monitor, so once its candidate storage is sized it must not
//! touch the heap. A counting global allocator (per thread, armed only around the measured
//! section) proves it.

use fdd_diagnostics::isolation::{Candidates, Diagnosis, SignatureConfig, SignatureMatrix};
use fdd_diagnostics::Verdict;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::counted;

#[test]
fn isolation_allocates_nothing_per_step() {
    let m = SignatureMatrix::new(&SignatureConfig {
        tests: vec!["r1".into(), "r2".into(), "r3".into()],
        faults: vec!["a".into(), "b".into(), "c".into(), "d".into()],
        rows: vec!["1 0 1 0".into(), "0 1 1 0".into(), "1 1 X 1".into()],
    })
    .expect("valid");
    let mut out = Candidates::for_matrix(&m);
    let verdicts = [
        Verdict::Failed,
        Verdict::Passed,
        Verdict::NotTested,
        Verdict::PreFailed,
        Verdict::PrePassed,
    ];
    let (seen, n) = counted(|| {
        let mut seen = [0usize; 3];
        for k in 0..10_000usize {
            let v = [
                verdicts[k % 5],
                verdicts[(k / 5) % 5],
                verdicts[(k / 25) % 5],
            ];
            m.isolate(&v, &mut out);
            seen[match out.diagnosis() {
                Diagnosis::NoFault => 0,
                Diagnosis::Isolated => 1,
                Diagnosis::Unknown => 2,
            }] += 1;
        }
        seen
    });
    assert_eq!(n, 0, "isolation allocated {n} times");
    assert!(
        seen.iter().all(|&s| s > 0),
        "every diagnosis was exercised: {seen:?}"
    );
    // The counter does count: a Vec in the armed section is seen.
    let (_, n) = counted(|| Vec::<u8>::with_capacity(16));
    assert_eq!(n, 1);
}
