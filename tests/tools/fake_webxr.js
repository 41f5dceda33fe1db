// A WebXR device stand-in for the browser tests (page.add_init_script): immersive-vr supported, a session whose
// frames the test plays with __xrStep(n), and two controllers (left, right) that three.js connects when the test
// calls __xrConnect(): their target-ray poses are window.__xrPoses[hand] (column-major 4 x 4), and
// __xrPress(hand, 'selectstart' | 'selectend' | 'squeezestart' | 'squeezeend') presses their buttons.
(() => {
  const at = (x, y, z) => new Float32Array([1,0,0,0, 0,1,0,0, 0,0,1,0, x,y,z,1]);
  window.__xrPoses = { left: at(-0.35, 1.1, -0.3), right: at(0.2, 1.1, -0.3) };
  const source = (hand) => ({ handedness: hand, targetRayMode: 'tracked-pointer', profiles: [],
                              targetRaySpace: { hand }, gripSpace: null,
                              gamepad: { axes: [0, 0, 0, 0], buttons: [] } });
  class FakeSession extends EventTarget {
    constructor() { super(); this.renderState = {}; this.inputSources = [source('left'), source('right')];
                    this.enabledFeatures = ['local-floor']; this.environmentBlendMode = 'opaque';
                    this.visibilityState = 'visible'; this.callbacks = []; }
    updateRenderState(state) { Object.assign(this.renderState, state); }
    async requestReferenceSpace(type) {
      const space = { type, getOffsetReferenceSpace: () => space, addEventListener() {}, removeEventListener() {} };
      return space;
    }
    requestAnimationFrame(callback) { this.callbacks.push(callback); return this.callbacks.length; }
    cancelAnimationFrame() {}
    async end() { this.dispatchEvent(new Event('end')); }
  }
  // The eye: window.__xrEyeMatrix when a test sets it first (column-major 4 x 4), else 1.6 m up looking ahead.
  const eye = { eye: 'left', transform: { matrix: new Float32Array(window.__xrEyeMatrix || [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,1.6,0,1]) },
                projectionMatrix: new Float32Array([1,0,0,0, 0,1.33,0,0, 0,0,-1.002,-1, 0,0,-0.2,0]) };
  const frame = (session) => ({ session, getViewerPose: () => ({ views: [eye] }),
                                getPose: (space) => (space && space.hand ? { transform: { matrix: window.__xrPoses[space.hand] } } : null) });
  window.__xrStep = (n = 1) => {
    for (let i = 0; i < n; i++) {
      const session = window.__xrSession, pending = session.callbacks.splice(0);
      for (const callback of pending) callback(performance.now(), frame(session));
    }
  };
  window.__xrConnect = () => {
    const session = window.__xrSession, event = new Event('inputsourceschange');
    event.added = session.inputSources;
    event.removed = [];
    session.dispatchEvent(event);
  };
  window.__xrPress = (hand, type) => {
    const session = window.__xrSession, event = new Event(type);
    event.inputSource = session.inputSources.find((s) => s.handedness === hand);
    event.frame = frame(session);
    session.dispatchEvent(event);
  };
  window.XRWebGLLayer = class {
    constructor() {
      this.framebuffer = null; this.framebufferWidth = 640; this.framebufferHeight = 480; this.ignoreDepthValues = true;
    }
    getViewport() { return { x: 0, y: 0, width: 640, height: 480 }; }
  };
  delete window.XRWebGLBinding;
  WebGL2RenderingContext.prototype.makeXRCompatible = async function () {};
  const xr = new EventTarget();
  xr.isSessionSupported = async (mode) => mode === 'immersive-vr';
  xr.requestSession = async () => (window.__xrSession = new FakeSession());
  Object.defineProperty(Navigator.prototype, 'xr', { get: () => xr, configurable: true });
})();
