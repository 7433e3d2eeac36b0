// Runs three.js's CSM addon (CSM.js with CSMFrustum.js, from the folder given as the first argument,
// vendor/ by default) on camera poses given as JSON on
// standard input and prints, as JSON, what it computes for each pose: the breaks (fractions of the
// shadow far distance), each cascade's shadow-camera box (left/right/top/bottom/near/far), the light's
// position, the light-space basis CSM.update() builds and the box centre in that basis.
//
// Input: {"csm": {cascades, maxFar, mode, shadowMapSize, lightMargin, lightNear, lightFar},
//         "light_direction": [x, y, z],
//         "poses": [{"fov_y_deg", "aspect", "near", "far", "position": [3], "right": [3], "up": [3], "back": [3]}]}
// (the camera-to-world axes; three.js cameras look down their -Z, "back").
import { readFileSync, writeFileSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = dirname( fileURLToPath( import.meta.url ) );
const shim = pathToFileURL( join( here, 'three_shim.mjs' ) ).href;
const addon = process.argv[ 2 ] || join( here, 'vendor' );

// The vendored files import 'three' (and CSM.js './CSMShader.js'): copies with those imports pointed
// at the shim, the code otherwise as vendored.
const work = mkdtempSync( join( tmpdir(), 'threejs_csm_' ) );
for ( const name of [ 'CSM.js', 'CSMFrustum.js' ] ) {
	const text = readFileSync( join( addon, name ), 'utf8' )
		.replace( /from 'three';/g, `from '${shim}';` )
		.replace( "import { CSMShader } from './CSMShader.js';", `import { CSMShader } from '${shim}';` );
	writeFileSync( join( work, name.replace( /\.js$/, '.mjs' ) ), text.replace( "'./CSMFrustum.js'", "'./CSMFrustum.mjs'" ) );
}
const { CSM } = await import( pathToFileURL( join( work, 'CSM.mjs' ) ).href );
const { Vector3, Matrix4, PerspectiveCamera } = await import( shim );
rmSync( work, { recursive: true } );

const input = JSON.parse( readFileSync( 0, 'utf8' ) );
const lightDirection = new Vector3( ...input.light_direction ).normalize();
const out = [];
for ( const pose of input.poses ) {
	const camera = new PerspectiveCamera( pose.fov_y_deg, pose.aspect, pose.near, pose.far );
	const e = camera.matrixWorld.elements;
	[ pose.right, pose.up, pose.back, pose.position ].forEach( ( v, c ) => { e[ 4 * c ] = v[ 0 ]; e[ 4 * c + 1 ] = v[ 1 ]; e[ 4 * c + 2 ] = v[ 2 ]; } );
	const parent = { add() {}, remove() {} };
	const csm = new CSM( { ...input.csm, camera, parent, lightDirection } );
	csm.update();
	// The basis CSM.update() uses: _lightOrientationMatrix.lookAt( _origin, lightDirection, _up = +Y ).
	const basis = new Matrix4().lookAt( new Vector3(), lightDirection, new Vector3( 0, 1, 0 ) ).elements;
	const axes = [ 0, 1, 2 ].map( ( c ) => [ basis[ 4 * c ], basis[ 4 * c + 1 ], basis[ 4 * c + 2 ] ] );
	out.push( {
		breaks: csm.breaks.slice(),
		shadow_far: Math.min( camera.far, csm.maxFar ),
		light_axes: axes,
		cascades: csm.lights.map( ( light, i ) => {
			const cam = light.shadow.camera, p = light.position;
			const centre = axes.map( ( a ) => a[ 0 ] * p.x + a[ 1 ] * p.y + a[ 2 ] * p.z );
			return {
				left: cam.left, right: cam.right, top: cam.top, bottom: cam.bottom, near: cam.near, far: cam.far,
				position: [ p.x, p.y, p.z ], centre_light: centre,
				slice_near_z: - csm.frustums[ i ].vertices.near[ 0 ].z, slice_far_z: - csm.frustums[ i ].vertices.far[ 0 ].z,
			};
		} ),
	} );
}
process.stdout.write( JSON.stringify( out ) );
