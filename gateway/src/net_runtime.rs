//! The network runtime: a current-thread tokio runtime on its own thread
//! (`fois-net`) that runs the Modbus TCP server and the MQTT client's
//! event loop. The state machine and its disk queue run on the gateway's
//! main runtime ([`crate::service`]); the queue's writes, `fdatasync`s and
//! renames block only that thread, so a slow or stalled disk delays
//! publishing but neither a Modbus answer nor the MQTT keep-alive.

use std::future::Future;
use std::thread::JoinHandle;

use anyhow::Context;
use tokio::runtime::Handle;
use tokio::sync::oneshot;
use tokio::task::JoinHandle as TaskHandle;

/// The running network runtime; dropping it stops its tasks and joins
/// its thread.
pub struct NetRuntime {
    handle: Handle,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl NetRuntime {
    /// Start the runtime's thread.
    pub fn start() -> anyhow::Result<NetRuntime> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("cannot start the network runtime")?;
        let handle = rt.handle().clone();
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("fois-net".into())
            .spawn(move || {
                rt.block_on(async {
                    let _ = stopped.await;
                });
            })
            .context("cannot start the network thread")?;
        Ok(NetRuntime {
            handle,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Run `task` on the network runtime.
    pub fn spawn<F>(&self, task: F) -> TaskHandle<F::Output>
    where
        F: Future + Send + 'static,
        F::Output: Send + 'static,
    {
        self.handle.spawn(task)
    }
}

impl Drop for NetRuntime {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
