/*  A complete check of SWI-Prolog 9.0.4's fast-term bytes, for fast_term_check.pl.

    fast_term_serialized/2 and fast_read/2 trust their input: the decoder
    (pl-rec.c, copy_record()) allocates the global-stack cells the header
    announces and writes what the opcodes say, with no bounds checks, so
    a wrong cell count, an out-of-range variable number, an unknown
    opcode or a length past the end aborts the process (an assertion) or
    corrupts its memory. This file walks the bytes once, as the decoder
    would, and accepts only what fast_term_serialized/2 itself writes for
    a term without attributed variables, cycles or rationals:

      byte 0      0x76  an integer only: N (1..8), N bytes big-endian
                  0x7a  an atom only: an atom opcode (below)
                  0x72  a ground term, 0x62 a term with variables:
                        varint code size, varint cells (global stack),
                        [varint variables, for 0x62], code
      opcodes     1 variable (varint number, in order of first use)
                  3 integer outside the tagged range (N, N bytes)
                  4 tagged integer (N, N bytes, within the tagged range)
                  6 string (varint length, 'B' + bytes, or 'W' 0 0 0 +
                    UCS-4 little-endian, one code above 255 at least)
                  8 list cell, 9 [], 11 atom (varint length, bytes),
                  12 wide atom (varint length, UCS-4 LE, one code above
                    255 at least), 13 compound (varint arity, then 9, 11
                    or 12 for its name, or 10 for a dict: an odd arity,
                    the tag a variable or an atom, then value-key pairs,
                    each key an atom or a tagged integer, all different;
                    the decoder sorts them), 14 float (8 bytes),
                  18 big integer (4-byte signed size S, |S| bytes of
                    magnitude, first non-zero, outside int64)
      cells       compound arity+1, list cell 3, float 3, integer 3,
                  string (len+8)/8 + 2, big integer ceil(|S|/8) + 3

    A varint is big-endian base 128, the high bit set on all bytes but
    the last (at most 9 bytes here). The code must be exactly the code
    size long, the cells counted must be exactly the header's, and every
    variable number must be below the count in the header with all of
    them used. Nesting is counted as term_depth_within/2 counts it (a
    list's elements one level below the list, however long), and bounded
    by the caller. The walk keeps one small frame per open level (at most
    MaxDepth+1), so its memory is bounded by the depth allowed, its time
    linear in the number of opcodes (a string's or atom's bytes are
    skipped, except a wide one's code points).

    fast_term_check(+Bytes, +MaxDepth, -Result): Result is `true`, or an
    atom naming the first fault. Bytes is a string of code points below
    256; a string with wider ones gives `not_bytes`.

    fast_term_stream_read(+Stream, +Len, +MaxDepth, -Term, -Result): read Len
    bytes from Stream (Sfread(): in bulk on a stream that records no
    position), check them as above and, if they pass, decode them into
    Term with PL_recorded_external() (what fast_term_serialized/2 does
    with a string): no Prolog string of the body is made. Result is
    `true`, a fault, or `truncated` if the stream ended first; an I/O
    error or timeout of the stream is raised. A body of up to 4 MiB is
    read into one buffer of its size (growing one from 64 KiB cost a
    tenth more CPU at 1 MB); a larger one into a buffer that doubles
    from 4 MiB as the bytes arrive, so a header that claims more than
    is sent costs at most 4 MiB or twice what was sent.
*/
#include <SWI-Stream.h>
#include <SWI-Prolog.h>
#include <stdlib.h>
#include <string.h>
#include <stdint.h>

#define OP_VAR        1
#define OP_INTEGER    3
#define OP_TAGGED     4
#define OP_STRING     6
#define OP_CONS       8
#define OP_NIL        9
#define OP_DICT      10
#define OP_ATOM      11
#define OP_WATOM     12
#define OP_COMPOUND  13
#define OP_FLOAT     14
#define OP_MPZ       18

#define HDR_TERM      0x62
#define HDR_GROUND    0x72
#define HDR_INT       0x76
#define HDR_ATOM      0x7a

#define TAGGED_MAX    ((int64_t)0x00ffffffffffffffLL)	/* max_tagged_integer */
#define TAGGED_MIN    (-TAGGED_MAX - 1)
#define MAX_CELLS     ((uint64_t)1 << 31)
#define FIRST_BUFFER  ((int64_t)4 << 20)	/* bodies up to 4 MiB: one buffer */

typedef struct
{ const unsigned char *b;
  size_t len;
  size_t pos;
} input;

#define LV_PLAIN 0
#define LV_LIST  1			/* a list cell's level: its tail stays here */
#define LV_DICT  2			/* a dict: tag, then value-key pairs */

typedef struct
{ uint64_t left;			/* terms still to read at this level */
  uint64_t arity;
  int      kind;			/* LV_* */
  size_t   keys;			/* a dict's first key in the key array */
} level;

typedef struct				/* a dict's key: atom text or small int */
{ const unsigned char *text;		/* NULL for an integer */
  size_t   len;
  int      op;
  int64_t  ival;
} dict_key;

typedef struct
{ dict_key *at;
  size_t    n, cap;
} key_array;

static int
compare_keys(const void *a, const void *b)
{ const dict_key *x = a, *y = b;

  if ( x->op != y->op )
    return x->op < y->op ? -1 : 1;
  if ( !x->text )
    return x->ival < y->ival ? -1 : x->ival > y->ival ? 1 : 0;
  if ( x->len != y->len )
    return x->len < y->len ? -1 : 1;
  return memcmp(x->text, y->text, x->len);
}

/* The keys of the dict whose first key is keys[from] are all different */
static int
keys_unique(key_array *keys, size_t from)
{ size_t i, n = keys->n - from;
  dict_key *k = keys->at + from;

  if ( n > 1 )
  { qsort(k, n, sizeof(*k), compare_keys);
    for(i = 1; i < n; i++)
    { if ( compare_keys(&k[i-1], &k[i]) == 0 )
	return FALSE;
    }
  }
  keys->n = from;
  return TRUE;
}

static int
add_key(key_array *keys, const dict_key *k)
{ if ( keys->n == keys->cap )
  { size_t cap = keys->cap ? keys->cap*2 : 16;
    dict_key *at = realloc(keys->at, cap * sizeof(*at));
    if ( !at )
      return FALSE;
    keys->at = at;
    keys->cap = cap;
  }
  keys->at[keys->n++] = *k;
  return TRUE;
}

static int
varint(input *in, uint64_t *v)
{ uint64_t x = 0;
  int i;

  for(i = 0; i < 9 && in->pos < in->len; i++)
  { unsigned char c = in->b[in->pos++];

    if ( i == 0 && c == 0x80 )
      return FALSE;			/* a leading zero group: not written */
    x = (x << 7) | (c & 0x7f);
    if ( !(c & 0x80) )
    { *v = x;
      return TRUE;
    }
  }
  return FALSE;				/* too long (> 63 bits) or cut short */
}

/* The bytes addInt64() uses for v: the fewest N with |v| < 2^(8N-1), at
   least 1 and 2 from 128 on (its loop never tries 1 byte for |v| >= 128) */
static unsigned
int64_bytes(int64_t v)
{ uint64_t a;
  unsigned n;

  if ( v == INT64_MIN )
    return 8;
  a = (uint64_t)(v < 0 ? -v : v);
  if ( a < 128 )
    return 1;
  for(n = 2; n < 8; n++)
  { if ( a < ((uint64_t)1 << (8*n-1)) )
      return n;
  }
  return 8;
}

/* N (1..8) then N bytes, big-endian two's complement, as addInt64() writes */
static int
int64_field(input *in, int64_t *v)
{ unsigned n, i;
  uint64_t x = 0;

  if ( in->pos >= in->len )
    return FALSE;
  n = in->b[in->pos++];
  if ( n < 1 || n > 8 || in->len - in->pos < n )
    return FALSE;
  for(i = 0; i < n; i++)
    x = (x << 8) | in->b[in->pos++];
  if ( n < 8 && (x & ((uint64_t)1 << (8*n-1))) )
    x |= ~(uint64_t)0 << (8*n);		/* sign extension */
  *v = (int64_t)x;
  return n == int64_bytes(*v);		/* as written, not padded */
}

/* n bytes of UCS-4 little-endian code points: all valid, one above 255 */
static int
ucs4_ok(const unsigned char *p, size_t n)
{ size_t i;
  int wide = FALSE;

  if ( n == 0 || n % 4 != 0 )
    return FALSE;
  for(i = 0; i < n; i += 4)
  { uint32_t c = (uint32_t)p[i] | (uint32_t)p[i+1] << 8 |
		 (uint32_t)p[i+2] << 16 | (uint32_t)p[i+3] << 24;
    if ( c > 0x10ffff )
      return FALSE;
    if ( c > 0xff )
      wide = TRUE;
  }
  return wide;
}

static const char *
atom_text(input *in, int op, uint64_t *len)
{ uint64_t n;

  if ( !varint(in, &n) )
    return "bad_varint";
  if ( n > in->len - in->pos )
    return "atom_past_end";
  if ( op == OP_WATOM && !ucs4_ok(in->b + in->pos, (size_t)n) )
    return "bad_wide_atom";
  in->pos += (size_t)n;
  if ( len )
    *len = n;
  return NULL;
}

static const char *
check_code(input *in, uint64_t want_cells, uint64_t nvars, size_t max_depth)
{ level *stack;
  size_t sp = 0, cap = 64;
  uint64_t cells = 0, seen = 0;
  const char *err = NULL;
  key_array keys = { NULL, 0, 0 };

  if ( !(stack = malloc(cap * sizeof(*stack))) )
    return "no_memory";
  stack[0].left = 1;			/* the root term */
  stack[0].arity = 1;
  stack[0].kind = LV_PLAIN;

  for(;;)
  { int op, is_dict = FALSE;
    uint64_t arity = 0;
    int opens = FALSE, is_cons = FALSE;

    while ( stack[sp].left == 0 )	/* levels read completely */
    { if ( stack[sp].kind == LV_DICT && !keys_unique(&keys, stack[sp].keys) )
      { err = "duplicate_key";
	goto out;
      }
      if ( sp == 0 )
	goto done;
      sp--;
    }
    if ( in->pos >= in->len )
    { err = "code_past_end";
      break;
    }
    op = in->b[in->pos++];
    if ( stack[sp].kind == LV_DICT )	/* dict(Tag, V1, K1, V2, K2, ...) */
    { uint64_t slot = stack[sp].arity - stack[sp].left;

      if ( slot == 0 )			/* the tag: a variable or an atom */
      { if ( op != OP_VAR && op != OP_ATOM && op != OP_WATOM )
	{ err = "bad_dict_tag"; goto out; }
      } else if ( slot % 2 == 0 )	/* a key: an atom or a small integer */
      { dict_key k;

	if ( op == OP_ATOM || op == OP_WATOM )
	{ uint64_t n;
	  if ( (err = atom_text(in, op, &n)) )
	    goto out;
	  k.text = in->b + in->pos - n;
	  k.len = (size_t)n;
	} else if ( op == OP_TAGGED )
	{ if ( !int64_field(in, &k.ival) ||
	       k.ival < TAGGED_MIN || k.ival > TAGGED_MAX )
	  { err = "bad_integer"; goto out; }
	  k.text = NULL;
	  k.len = 0;
	} else
	{ err = "bad_dict_key"; goto out; }
	k.op = op;
	if ( !add_key(&keys, &k) )
	{ err = "no_memory"; goto out; }
	stack[sp].left--;
	continue;			/* atomic: no cells, nothing opens */
      }
    }
    stack[sp].left--;

    switch(op)
    { case OP_VAR:
      { uint64_t n;
	if ( !varint(in, &n) )
	{ err = "bad_varint"; goto out; }
	if ( n > seen || n >= nvars )
	{ err = "bad_variable"; goto out; }
	if ( n == seen )
	  seen++;
	break;
      }
      case OP_INTEGER:
      case OP_TAGGED:
      { int64_t v;
	int tagged_range;
	if ( !int64_field(in, &v) )
	{ err = "bad_integer"; goto out; }
	tagged_range = (v >= TAGGED_MIN && v <= TAGGED_MAX);
	if ( (op == OP_TAGGED) != tagged_range )
	{ err = "bad_integer"; goto out; }
	if ( op == OP_INTEGER )
	  cells += 3;
	break;
      }
      case OP_MPZ:
      { int32_t s;
	uint64_t m;
	const unsigned char *p;
	if ( in->len - in->pos < 4 )
	{ err = "bigint_past_end"; goto out; }
	p = in->b + in->pos;
	s = (int32_t)((uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 |
		      (uint32_t)p[2] << 8 | (uint32_t)p[3]);
	in->pos += 4;
	m = (s < 0) ? (uint64_t)(-(int64_t)s) : (uint64_t)s;
	if ( m < 8 || m > in->len - in->pos )
	{ err = "bad_bigint"; goto out; }
	p = in->b + in->pos;
	if ( p[0] == 0 )
	{ err = "bad_bigint"; goto out; }
	if ( m == 8 )			/* must not fit an int64 */
	{ int rest_zero = TRUE, i;
	  for(i = 1; i < 8; i++)
	    if ( p[i] )
	      rest_zero = FALSE;
	  if ( p[0] < 0x80 || (s < 0 && p[0] == 0x80 && rest_zero) )
	  { err = "bad_bigint"; goto out; }	/* below 2^63, or -2^63 */
	}
	in->pos += (size_t)m;
	cells += (m + 7) / 8 + 3;
	break;
      }
      case OP_STRING:
      { uint64_t n;
	const unsigned char *p;
	if ( !varint(in, &n) )
	{ err = "bad_varint"; goto out; }
	if ( n < 1 || n > in->len - in->pos )
	{ err = "string_past_end"; goto out; }
	p = in->b + in->pos;
	if ( p[0] == 'W' )
	{ if ( n < 8 || p[1] || p[2] || p[3] || !ucs4_ok(p+4, (size_t)n-4) )
	  { err = "bad_wide_string"; goto out; }
	} else if ( p[0] != 'B' )
	{ err = "bad_string"; goto out; }
	in->pos += (size_t)n;
	cells += (n + 8) / 8 + 2;
	break;
      }
      case OP_NIL:
	break;
      case OP_ATOM:
      case OP_WATOM:
	if ( (err = atom_text(in, op, NULL)) )
	  goto out;
	break;
      case OP_FLOAT:
	if ( in->len - in->pos < 8 )
	{ err = "float_past_end"; goto out; }
	in->pos += 8;
	cells += 3;
	break;
      case OP_CONS:
	arity = 2;
	opens = TRUE;
	is_cons = TRUE;
	cells += 3;
	break;
      case OP_COMPOUND:
      { int nop;
	if ( !varint(in, &arity) )
	{ err = "bad_varint"; goto out; }
	if ( arity > in->len )		/* each argument takes a byte */
	{ err = "bad_arity"; goto out; }
	if ( in->pos >= in->len )
	{ err = "code_past_end"; goto out; }
	nop = in->b[in->pos++];
	if ( nop == OP_ATOM || nop == OP_WATOM )
	{ uint64_t n;
	  if ( (err = atom_text(in, nop, &n)) )
	    goto out;
	  if ( arity == 2 && nop == OP_ATOM && n == 3 &&
	       memcmp(in->b + in->pos - 3, "[|]", 3) == 0 )
	  { err = "bad_functor_name";	/* a list cell is written as 8 */
	    goto out;
	  }
	} else if ( nop == OP_DICT )
	{ if ( arity % 2 != 1 )		/* a tag and pairs */
	  { err = "bad_dict"; goto out; }
	  is_dict = TRUE;
	} else if ( nop != OP_NIL )
	{ err = "bad_functor_name"; goto out; }
	cells += arity + 1;
	opens = (arity > 0);
	break;
      }
      default:
	err = "bad_opcode";
	goto out;
    }

    if ( cells > want_cells )
    { err = "cells_mismatch";
      break;
    }
    if ( opens )
    { if ( is_cons && stack[sp].kind == LV_LIST && stack[sp].left == 0 )
      { stack[sp].left = 2;		/* the tail of a list: same level */
      } else
      { if ( sp + 1 > max_depth )
	{ err = "too_deep";
	  break;
	}
	if ( sp + 1 >= cap )
	{ level *s2;
	  cap *= 2;
	  if ( !(s2 = realloc(stack, cap * sizeof(*stack))) )
	  { err = "no_memory";
	    break;
	  }
	  stack = s2;
	}
	sp++;
	stack[sp].left = arity;
	stack[sp].arity = arity;
	stack[sp].kind = is_cons ? LV_LIST : is_dict ? LV_DICT : LV_PLAIN;
	stack[sp].keys = keys.n;
      }
    }
  }
  goto out;

done:
  if ( in->pos != in->len )
    err = "trailing_bytes";
  else if ( cells != want_cells )
    err = "cells_mismatch";
  else if ( seen != nvars )
    err = "variables_mismatch";

out:
  free(stack);
  free(keys.at);
  return err;
}

static const char *
check_bytes(const unsigned char *b, size_t len, size_t max_depth)
{ input in = { b, len, 0 };
  uint64_t csize, cells, nvars = 0;
  int hdr;

  if ( len < 2 )
    return "too_short";
  hdr = b[in.pos++];
  switch(hdr)
  { case HDR_INT:
    { int64_t v;
      if ( !int64_field(&in, &v) || in.pos != len )
	return "bad_integer";
      return NULL;
    }
    case HDR_ATOM:
    { int op = b[in.pos++];
      const char *err;
      if ( op == OP_NIL )
	return in.pos == len ? NULL : "trailing_bytes";
      if ( op != OP_ATOM && op != OP_WATOM )
	return "bad_opcode";
      if ( (err = atom_text(&in, op, NULL)) )
	return err;
      return in.pos == len ? NULL : "trailing_bytes";
    }
    case HDR_GROUND:
    case HDR_TERM:
      break;
    default:
      return "bad_header";
  }
  if ( !varint(&in, &csize) || !varint(&in, &cells) )
    return "bad_header";
  if ( hdr == HDR_TERM && (!varint(&in, &nvars) || nvars == 0) )
    return "bad_header";
  if ( csize < len - in.pos )
    return "trailing_bytes";		/* bytes after the term */
  if ( csize > len - in.pos )
    return "code_past_end";
  if ( cells >= MAX_CELLS || nvars > len )
    return "bad_header";
  return check_code(&in, cells, nvars, max_depth);
}

static foreign_t
fast_term_check(term_t bytes, term_t max_depth, term_t result)
{ char *s;
  size_t len;
  int64_t depth;
  const char *err;

  if ( !PL_get_int64_ex(max_depth, &depth) )
    return FALSE;
  if ( depth < 0 )
    return PL_domain_error("not_less_than_zero", max_depth);
  /* PL_get_string() points into the string itself and fails on a wide
     one (code points above 255: not bytes) */
  if ( !PL_get_string(bytes, &s, &len) )
  { if ( PL_is_string(bytes) )
      return PL_unify_atom_chars(result, "not_bytes");
    return PL_type_error("string", bytes);
  }
  err = check_bytes((const unsigned char *)s, len, (size_t)depth);
  return PL_unify_atom_chars(result, err ? err : "true");
}


static foreign_t
fast_term_read(term_t stream, term_t tlen, term_t max_depth, term_t term,
	       term_t result)
{ IOSTREAM *s;
  int64_t len, depth;
  size_t cap, got = 0;
  char *buf;
  const char *err = NULL;
  int rc;

  if ( !PL_get_int64_ex(tlen, &len) || !PL_get_int64_ex(max_depth, &depth) )
    return FALSE;
  if ( len < 0 )
    return PL_domain_error("not_less_than_zero", tlen);
  if ( depth < 0 )
    return PL_domain_error("not_less_than_zero", max_depth);
  if ( !PL_get_stream(stream, &s, SIO_INPUT) )
    return FALSE;
  cap = (len <= FIRST_BUFFER) ? (size_t)len : FIRST_BUFFER;
  if ( !(buf = malloc(cap ? cap : 1)) )
  { PL_release_stream(s);
    return PL_resource_error("memory");
  }
  while ( got < (size_t)len )
  { size_t n, want;

    if ( got == cap )
    { size_t cap2 = (cap*2 < (size_t)len) ? cap*2 : (size_t)len;
      char *b2 = realloc(buf, cap2);
      if ( !b2 )
      { free(buf);
	PL_release_stream(s);
	return PL_resource_error("memory");
      }
      buf = b2;
      cap = cap2;
    }
    want = cap - got;
    n = Sfread(buf+got, 1, want, s);	/* short only at the end or an error */
    got += n;
    if ( n < want )
    { if ( Sferror(s) )
      { free(buf);
	return PL_release_stream(s);	/* raises the stream's error */
      }
      break;				/* the end of the stream */
    }
  }
  if ( !PL_release_stream(s) )
  { free(buf);
    return FALSE;
  }
  if ( got < (size_t)len )
    err = "truncated";
  else
    err = check_bytes((const unsigned char *)buf, (size_t)len, (size_t)depth);
  if ( err )
  { free(buf);
    return PL_unify_atom_chars(result, err);
  }
  { term_t t = PL_new_term_ref();	/* PL_recorded_external() puts, */
					/* it does not unify */
    rc = PL_recorded_external(buf, t);
    free(buf);
    if ( !rc )
      return FALSE;			/* e.g. out of global stack: raised */
    return PL_unify(term, t) && PL_unify_atom_chars(result, "true");
  }
}

install_t
install_fast_term_check(void)
{ PL_register_foreign_in_module("fast_term_check", "fast_term_check", 3,
				fast_term_check, 0);
  PL_register_foreign_in_module("fast_term_check", "fast_term_stream_read", 5,
				fast_term_read, 0);
}
