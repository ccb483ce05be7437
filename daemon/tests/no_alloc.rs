//! The per-sample path allocates nothing: receive → check → model → publish, measured
//! with a counting global allocator on the test's own thread after a warm-up.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;

use ghnet_client::testing::TestNamespace;
use ghnet_client::{
    HeadingEstimate, HeadingPublisher, VelocityPublisher, VelocitySample, VelocitySubscriber,
};
use ghnetd::answer::{Batch, Limits, ModelTag, Tracker};

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCS.with(|a| a.set(a.get() + 1));
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCS.with(|a| a.set(a.get() + 1));
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f` on this thread.
fn allocations(f: impl FnOnce()) -> u64 {
    ALLOCS.with(|a| a.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCS.with(|a| a.get())
}

/// What both tests need: a private iceoryx2 namespace with the three ports ghnetd
/// uses for one source, and the answer path's state on the `paper-s1` model.
struct Fixture {
    _ns: TestNamespace,
    gnss: VelocityPublisher,
    velocity: VelocitySubscriber,
    heading: HeadingPublisher,
    tag: ModelTag,
    predictor: ghnet_models::Predictor,
    limits: Limits,
    tracker: Tracker,
}

impl Fixture {
    fn new(namespace: &str, source: &str) -> Self {
        let ns = TestNamespace::new(namespace);
        let ipc = ns.ipc();
        let model = Arc::new(ghnet_models::Model::builtin("paper-s1").unwrap());
        Self {
            gnss: VelocityPublisher::new(&ipc, source).unwrap(),
            velocity: VelocitySubscriber::new(&ipc, source).unwrap(),
            heading: HeadingPublisher::new(&ipc, source).unwrap(),
            tag: ModelTag {
                id: model.id(),
                name: HeadingEstimate::encode_model_name(model.name()),
            },
            predictor: ghnet_models::Predictor::new(model),
            limits: Limits { max_speed: 100.0 },
            tracker: Tracker::default(),
            _ns: ns,
        }
    }
}

#[test]
fn receive_answer_publish_allocates_nothing() {
    let Fixture {
        _ns,
        gnss,
        velocity,
        heading,
        tag,
        mut predictor,
        limits,
        mut tracker,
    } = Fixture::new("noalloc", "n");

    // Warm-up: iceoryx2 connects ports lazily on first use.
    for seq in 0..3 {
        gnss.send(VelocitySample::new(seq, seq, 1.0, 2.0, 0.0))
            .unwrap();
        velocity.drain_notifications().unwrap();
        let s = velocity.try_recv().unwrap().unwrap();
        heading
            .send(tracker.answer(&s, &mut predictor, &limits, &tag))
            .unwrap();
    }

    let rounds = 200u64;
    let mut ours = 0;
    let mut publishes = 0;
    for seq in 3..3 + rounds {
        // Valid, stationary and invalid inputs all take allocation-free paths.
        let vn = match seq % 3 {
            0 => 1.0,
            1 => 0.0,
            _ => f32::NAN,
        };
        gnss.send(VelocitySample::new(seq, seq, vn, 2.0, 0.0))
            .unwrap();
        // What ghnetd's serve() does per wake-up and per sample.
        let mut answer = None;
        ours += allocations(|| {
            velocity.drain_notifications().unwrap();
            let s = velocity.try_recv().unwrap().unwrap();
            answer = Some(tracker.answer(&s, &mut predictor, &limits, &tag));
        });
        publishes += allocations(|| heading.publish(answer.unwrap()).unwrap());
        ours += allocations(|| heading.notify().unwrap());
    }
    assert_eq!(ours, 0, "allocations in receive/check/model/notify");
    // iceoryx2 0.10 itself allocates one small shared-state object per loan
    // (ChunkMutSharedState in loan_uninit); nothing more may be added on top.
    assert!(
        publishes <= rounds,
        "{publishes} allocations in {rounds} publishes"
    );
}

/// The batch path ghnetd takes when samples pile up (one source that fell behind,
/// or many that woke together): receive all, `Batch::book` each, one
/// `Batch::predict`, `Batch::finish` each (the three steps `serve_round` in
/// daemon/src/serve.rs takes with the same scratch), then publish each. Only
/// iceoryx2's own per-loan object may allocate.
#[test]
fn batch_path_allocates_nothing() {
    let Fixture {
        _ns,
        gnss,
        velocity,
        heading,
        tag,
        mut predictor,
        limits,
        mut tracker,
    } = Fixture::new("noallocb", "b");

    // The daemon's scratch, made once.
    const N: usize = 64;
    let mut batch = Batch::new(N);
    let mut answers = Vec::with_capacity(N);

    let mut ours = 0;
    let mut publishes = 0;
    let rounds = 6u64;
    for round in 0..rounds {
        for i in 0..N as u64 {
            let seq = round * N as u64 + i;
            // Valid, stationary and invalid inputs, as in the one-sample test.
            let vn = match seq % 3 {
                0 => 1.0,
                1 => 0.0,
                _ => f32::NAN,
            };
            gnss.publish(VelocitySample::new(seq, seq, vn, 2.0, 0.0))
                .unwrap();
        }
        gnss.notify().unwrap();
        // Round 0 is the warm-up (iceoryx2 connects ports lazily on first use).
        let counted = allocations(|| {
            velocity.drain_notifications().unwrap();
            batch.clear();
            while let Some(s) = velocity.try_recv().unwrap() {
                batch.samples.push(s);
            }
            assert_eq!(batch.samples.len(), N);
            for i in 0..N {
                batch.book(i, &mut tracker, &limits);
            }
            batch.predict(&mut predictor);
            answers.clear();
            for i in 0..N {
                answers.push(batch.finish(i, &mut tracker, &tag));
            }
        });
        assert_eq!(answers.len(), N);
        let mut published = 0;
        for a in &answers {
            published += allocations(|| heading.publish(*a).unwrap());
        }
        let notified = allocations(|| heading.notify().unwrap());
        if round > 0 {
            ours += counted + notified;
            publishes += published;
        }
    }
    assert_eq!(
        ours, 0,
        "allocations in the batch receive/check/model/notify"
    );
    let answered = (rounds - 1) * N as u64;
    assert!(
        publishes <= answered,
        "{publishes} allocations in {answered} publishes"
    );
    assert_eq!(tracker.counters.received, rounds * N as u64);
    assert_eq!(tracker.counters.gaps + tracker.counters.duplicates, 0);
}
