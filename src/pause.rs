//! Long computations give their thread back now and then.
//!
//! In the page the labels are spread, and captures packed, on the thread that also draws (wasm
//! has one): the walk over a large capture's points runs for seconds, and so does decoding a
//! capture's photos and fitting its feature autoencoder. So these are written as futures that
//! call [`Pause::pause`] between units of work: the page's pause yields to the browser once a
//! slice of time is used up, so it keeps drawing and taking input; the command line and the
//! tests pass [`NoPause`] and run them straight through ([`run_to_end`]).
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

/// Where a long computation may give its thread back: called between units of work (one
/// iteration of a solve), it resolves when the computation may go on.
pub trait Pause {
    fn pause(&mut self) -> impl Future<Output = ()>;
}

/// Never pauses: for callers with a thread to themselves.
pub struct NoPause;

impl Pause for NoPause {
    fn pause(&mut self) -> impl Future<Output = ()> {
        std::future::ready(())
    }
}

/// Runs a computation whose only pauses are [`NoPause`]'s, which never wait, to its end.
pub fn run_to_end<T>(work: impl Future<Output = T>) -> T {
    let mut work = pin!(work);
    match work.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(value) => value,
        Poll::Pending => panic!("run_to_end takes computations that pause only through NoPause"),
    }
}

/// Counts its pauses (tests check that a computation gives its thread back, and how often).
#[derive(Default)]
pub struct CountPauses(pub usize);

impl Pause for CountPauses {
    fn pause(&mut self) -> impl Future<Output = ()> {
        self.0 += 1;
        std::future::ready(())
    }
}

/// Resolves after `ms` milliseconds, through the browser's timer: the thread is the browser's
/// meanwhile.
#[cfg(target_arch = "wasm32")]
pub async fn sleep_ms(ms: u32) {
    let (done, elapsed) = futures_channel::oneshot::channel::<()>();
    gloo::timers::callback::Timeout::new(ms, move || {
        let _ = done.send(());
    })
    .forget();
    let _ = elapsed.await;
}
