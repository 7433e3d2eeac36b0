// The few parts of three.js's core that the CSM addon (vendor/CSM.js, vendor/CSMFrustum.js) calls,
// written for this test from three.js's documented semantics (column-major Matrix4, OpenGL clip space
// of PerspectiveCamera.updateProjectionMatrix / Matrix4.makePerspective, Matrix4.lookAt putting +Z from
// the target toward the eye). No rendering: a DirectionalLight is its position, its target and its
// shadow camera's box; ShaderChunk and CSMShader are empty, as the test never compiles a material.

export const MathUtils = {
	DEG2RAD: Math.PI / 180,
	lerp: ( x, y, t ) => ( 1 - t ) * x + t * y,
};

export class Vector2 {
	constructor( x = 0, y = 0 ) { this.x = x; this.y = y; }
}

export class Vector3 {
	constructor( x = 0, y = 0, z = 0 ) { this.x = x; this.y = y; this.z = z; }
	set( x, y, z ) { this.x = x; this.y = y; this.z = z; return this; }
	copy( v ) { this.x = v.x; this.y = v.y; this.z = v.z; return this; }
	clone() { return new Vector3( this.x, this.y, this.z ); }
	subVectors( a, b ) { this.x = a.x - b.x; this.y = a.y - b.y; this.z = a.z - b.z; return this; }
	addVectors( a, b ) { this.x = a.x + b.x; this.y = a.y + b.y; this.z = a.z + b.z; return this; }
	multiplyScalar( s ) { this.x *= s; this.y *= s; this.z *= s; return this; }
	lengthSq() { return this.x * this.x + this.y * this.y + this.z * this.z; }
	length() { return Math.sqrt( this.lengthSq() ); }
	normalize() { return this.multiplyScalar( 1 / ( this.length() || 1 ) ); }
	crossVectors( a, b ) {
		const x = a.y * b.z - a.z * b.y, y = a.z * b.x - a.x * b.z, z = a.x * b.y - a.y * b.x;
		return this.set( x, y, z );
	}
	distanceTo( v ) {
		const dx = this.x - v.x, dy = this.y - v.y, dz = this.z - v.z;
		return Math.sqrt( dx * dx + dy * dy + dz * dz );
	}
	lerpVectors( a, b, t ) {
		this.x = a.x + ( b.x - a.x ) * t; this.y = a.y + ( b.y - a.y ) * t; this.z = a.z + ( b.z - a.z ) * t;
		return this;
	}
	applyMatrix4( m ) {
		const x = this.x, y = this.y, z = this.z, e = m.elements;
		const w = 1 / ( e[ 3 ] * x + e[ 7 ] * y + e[ 11 ] * z + e[ 15 ] );
		this.x = ( e[ 0 ] * x + e[ 4 ] * y + e[ 8 ] * z + e[ 12 ] ) * w;
		this.y = ( e[ 1 ] * x + e[ 5 ] * y + e[ 9 ] * z + e[ 13 ] ) * w;
		this.z = ( e[ 2 ] * x + e[ 6 ] * y + e[ 10 ] * z + e[ 14 ] ) * w;
		return this;
	}
}

export class Matrix4 {
	constructor() { this.elements = [ 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 ]; }
	copy( m ) { this.elements = m.elements.slice(); return this; }
	multiplyMatrices( a, b ) {
		const ae = a.elements, be = b.elements, out = new Array( 16 );
		for ( let c = 0; c < 4; c ++ ) for ( let r = 0; r < 4; r ++ ) {
			let s = 0;
			for ( let k = 0; k < 4; k ++ ) s += ae[ k * 4 + r ] * be[ c * 4 + k ];
			out[ c * 4 + r ] = s;
		}
		this.elements = out;
		return this;
	}
	invert() {
		// Gauss-Jordan elimination with partial pivoting on the row-major copy.
		const e = this.elements, a = [];
		for ( let r = 0; r < 4; r ++ ) a.push( [ e[ r ], e[ 4 + r ], e[ 8 + r ], e[ 12 + r ], r === 0 ? 1 : 0, r === 1 ? 1 : 0, r === 2 ? 1 : 0, r === 3 ? 1 : 0 ] );
		for ( let c = 0; c < 4; c ++ ) {
			let p = c;
			for ( let r = c + 1; r < 4; r ++ ) if ( Math.abs( a[ r ][ c ] ) > Math.abs( a[ p ][ c ] ) ) p = r;
			[ a[ c ], a[ p ] ] = [ a[ p ], a[ c ] ];
			const d = a[ c ][ c ];
			for ( let k = 0; k < 8; k ++ ) a[ c ][ k ] /= d;
			for ( let r = 0; r < 4; r ++ ) if ( r !== c ) {
				const f = a[ r ][ c ];
				for ( let k = 0; k < 8; k ++ ) a[ r ][ k ] -= f * a[ c ][ k ];
			}
		}
		for ( let r = 0; r < 4; r ++ ) for ( let c = 0; c < 4; c ++ ) e[ c * 4 + r ] = a[ r ][ 4 + c ];
		return this;
	}
	lookAt( eye, target, up ) {
		// Rotation only (the translation is kept): +Z from the target toward the eye, X = up × Z, Y = Z × X.
		const z = new Vector3().subVectors( eye, target );
		if ( z.lengthSq() === 0 ) z.z = 1;
		z.normalize();
		const x = new Vector3().crossVectors( up, z );
		if ( x.lengthSq() === 0 ) {
			if ( Math.abs( up.z ) === 1 ) z.x += 0.0001; else z.z += 0.0001;
			z.normalize();
			x.crossVectors( up, z );
		}
		x.normalize();
		const y = new Vector3().crossVectors( z, x );
		const te = this.elements;
		te[ 0 ] = x.x; te[ 4 ] = y.x; te[ 8 ] = z.x;
		te[ 1 ] = x.y; te[ 5 ] = y.y; te[ 9 ] = z.y;
		te[ 2 ] = x.z; te[ 6 ] = y.z; te[ 10 ] = z.z;
		return this;
	}
	makePerspective( left, right, top, bottom, near, far ) {
		// WebGL clip space (z in [-1, 1]).
		const te = this.elements;
		const x = 2 * near / ( right - left ), y = 2 * near / ( top - bottom );
		const a = ( right + left ) / ( right - left ), b = ( top + bottom ) / ( top - bottom );
		const c = - ( far + near ) / ( far - near ), d = - 2 * far * near / ( far - near );
		te[ 0 ] = x; te[ 4 ] = 0; te[ 8 ] = a; te[ 12 ] = 0;
		te[ 1 ] = 0; te[ 5 ] = y; te[ 9 ] = b; te[ 13 ] = 0;
		te[ 2 ] = 0; te[ 6 ] = 0; te[ 10 ] = c; te[ 14 ] = d;
		te[ 3 ] = 0; te[ 7 ] = 0; te[ 11 ] = - 1; te[ 15 ] = 0;
		return this;
	}
}

export class Box3 {
	constructor() { this.min = new Vector3(); this.max = new Vector3(); this.makeEmpty(); }
	makeEmpty() { this.min.set( Infinity, Infinity, Infinity ); this.max.set( - Infinity, - Infinity, - Infinity ); return this; }
	isEmpty() { return this.max.x < this.min.x || this.max.y < this.min.y || this.max.z < this.min.z; }
	expandByPoint( p ) {
		this.min.set( Math.min( this.min.x, p.x ), Math.min( this.min.y, p.y ), Math.min( this.min.z, p.z ) );
		this.max.set( Math.max( this.max.x, p.x ), Math.max( this.max.y, p.y ), Math.max( this.max.z, p.z ) );
		return this;
	}
	getCenter( target ) {
		return this.isEmpty() ? target.set( 0, 0, 0 ) : target.addVectors( this.min, this.max ).multiplyScalar( 0.5 );
	}
}

class OrthographicShadowCamera {
	constructor() { this.left = - 5; this.right = 5; this.top = 5; this.bottom = - 5; this.near = 0.5; this.far = 500; }
	updateProjectionMatrix() {}
}

export class DirectionalLight {
	constructor( color, intensity ) {
		this.color = color; this.intensity = intensity; this.castShadow = false;
		this.position = new Vector3( 0, 1, 0 );
		this.target = { position: new Vector3() };
		this.shadow = { bias: 0, mapSize: { width: 512, height: 512 }, camera: new OrthographicShadowCamera() };
	}
}

export class PerspectiveCamera {
	// PerspectiveCamera.updateProjectionMatrix with zoom 1, no view offset and no film offset.
	constructor( fov, aspect, near, far ) {
		this.fov = fov; this.aspect = aspect; this.near = near; this.far = far; this.zoom = 1;
		this.projectionMatrix = new Matrix4(); this.matrixWorld = new Matrix4();
	}
	updateProjectionMatrix() {
		const top = this.near * Math.tan( MathUtils.DEG2RAD * 0.5 * this.fov ) / this.zoom;
		const height = 2 * top, width = this.aspect * height, left = - 0.5 * width;
		this.projectionMatrix.makePerspective( left, left + width, top, top - height, this.near, this.far );
	}
}

export const ShaderChunk = {};
export const CSMShader = { lights_fragment_begin: '', lights_pars_begin: '' };
