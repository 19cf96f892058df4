:- module(wire,
          [ frame_write/3,              % +Stream, +Kind, +Term
            frame_read/3,               % +Stream, -Frame, +Options
            wire_version/1,             % -Version
            text_term_bytes/2,          % ?Term, ?Bytes
            term_depth_within/2,        % @Term, +MaxDepth
            text_nesting_within/2       % +Text, +MaxDepth
          ]).
:- use_module(platform_errors, [wire_error/1]).
:- use_module(bulk_write, [write_bytes/2]).
:- use_module(fast_term_check, [fast_term_bytes_check/3, fast_term_read/5]).
:- use_module(term_nesting, [text_nesting_within/2, term_depth_within/2]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(utf8), [utf8_codes//1]).
:- use_module(library(lists), [append/3]).
:- use_module(library(error), [must_be/2]).
:- use_module(library(option), [option/3]).
:- use_module(library(memfile),
            [ new_memory_file/1, open_memory_file/4, free_memory_file/1 ]).

/** <module> Length-prefixed frames on a binary stream

A frame is a 12-byte header followed by a body:

  | bytes | meaning                                        |
  |-------|------------------------------------------------|
  | 0-3   | magic "DFRL"                                   |
  | 4     | protocol version (1)                           |
  | 5     | kind: "T" (text term) or "B" (binary term)     |
  | 6-7   | reserved, zero                                 |
  | 8-11  | body length in bytes, unsigned big-endian      |

Both kinds carry their real body length, and frame_read/3 checks it
against a limit before a single body byte is read, so a proxy or a test
can count and cut frames without decoding them. A text body is the term
written canonically (UTF-8) and is read back with read_term/3, so any
peer may send one. A binary body is the term as fast_term_serialized/2
writes it (SWI-Prolog's fast serialization): it is quick for large float
lists, but SWI-Prolog's decoder trusts its input, and one mutated byte
aborts the process (`copy_record: Assertion failed`). So a binary body
is read whole and checked completely before it is decoded
(fast_term_check.pl, in C where native/fast_term_check.c is built): the
decoder only ever sees bytes that fast_term_serialized/2 itself writes
for a plain term (no attributed variables, cycles or rationals)
at most max_depth(D) deep (default 10,000). frame_read/3 still accepts
a binary frame only when the caller says the connection is
authenticated (the peer proved a token of this node).

Streams that carry frames should record no position
(`set_stream(S, record_position(false))`, as transport.pl and the node's
connection workers do): SWI-Prolog then moves a binary body in bulk
instead of counting lines and columns byte by byte, which is most of
what reading a 1 MB frame costs. frame_read/3's option body_size(-Bytes)
tells the caller how large the frame was.

Before a peer has authenticated, a server reads with three more limits
(options of frame_read/3): the whole frame, from its first byte to its
last, must arrive within a deadline (deadline(Sec)); the peer sends one
frame and waits for its answer (no pipelining before authentication);
and the parsed term may be at most max_depth(D) deep (a list counts as
one level, whatever its length; an operator chain such as `a+a+...+a`
is as deep as it is long). Before read_term/3 sees the text, its
brackets ( `(`, `[`, `{` outside quoted text, `0'c` codes and comments)
are counted in one pass (text_nesting_within/2): a text nested deeper
than D is refused unread, since read_term/3 recurses on the C stack for
every bracket level (16,000 levels overflow a thread's C stack, and the
pages it touched stay resident in a pooled worker). read_term/3 parses
in time linear in the text for every shape tried (chains of infix,
prefix and mixed operators, nested brackets), and every check after it
is linear too, so a frame's cost is bounded by its size. The deadline
reader keeps its chunks in one open list, so reading a frame is linear
in its size however it is split. Option parse_slots(Queue, Over) makes
the decoding of a text body over Over bytes wait for a slot (a message
of Queue, a counting semaphore), so that a server bounds how many
unauthenticated frames are parsed at once.
*/

wire_version(1).

magic([0'D, 0'F, 0'R, 0'L]).

kind_byte(text,   0'T).
kind_byte(binary, 0'B).

%!  frame_write(+Stream, +Kind, +Term) is det.
%
%   Write Term as one frame of Kind (`text` or `binary`) and flush.

frame_write(Stream, Kind, Term) :-
    body_bytes(Kind, Term, Body),
    string_length(Body, Len),
    (   Len > 0xffffffff
    ->  wire_error(too_large(Len, 0xffffffff))
    ;   true
    ),
    header(Kind, Len, Header),
    write(Stream, Header),
    (   Len > 8192
    ->  write_bytes(Stream, Body)       % in one piece (bulk_write.pl)
    ;   write(Stream, Body)
    ),
    flush_output(Stream).

%   The header as one string of bytes, written with one write/2 (twelve
%   put_byte/2 calls took as long as encoding a small text body).
header(Kind, Len, Header) :-
    kind_byte(Kind, K),
    wire_version(V),
    magic(M),
    B0 is (Len >> 24) /\ 0xff,
    B1 is (Len >> 16) /\ 0xff,
    B2 is (Len >> 8) /\ 0xff,
    B3 is Len /\ 0xff,
    append(M, [V, K, 0, 0, B0, B1, B2, B3], Codes),
    string_codes(Header, Codes).

body_bytes(text, Term, Body) :-
    text_term_bytes(Term, Codes),
    string_codes(Body, Codes).
body_bytes(binary, Term, Body) :-
    fast_term_serialized(Term, Body).

%!  text_term_bytes(?Term, ?Bytes) is det.
%
%   Bytes is the UTF-8 encoding of Term written canonically and
%   terminated by " .". In mode (-,+) the term is read with read_term/3;
%   a syntax error raises wire_error(syntax(Detail)).

text_term_bytes(Term, Bytes) :-
    var(Bytes),
    !,
    format(string(Text), "~k .~n", [Term]),
    string_bytes(Text, Bytes, utf8).
text_term_bytes(Term, Bytes) :-
    (   phrase(utf8_codes(Codes), Bytes)
    ->  true
    ;   wire_error(syntax(not_utf8))
    ),
    setup_call_cleanup(
        open_codes_stream(Codes, In),
        read_text_term(In, Term),
        close(In)).

read_text_term(In, Term) :-
    catch(read_term(In, Term0, [syntax_errors(error)]), E, bad_syntax(E)),
    (   Term0 == end_of_file
    ->  wire_error(syntax(empty))
    ;   true
    ),
    catch(read_term(In, Rest, [syntax_errors(error)]), E2, bad_syntax(E2)),
    (   Rest == end_of_file
    ->  Term = Term0
    ;   wire_error(syntax(trailing_data))
    ).

bad_syntax(error(syntax_error(What), _)) :-
    !,
    wire_error(syntax(What)).
bad_syntax(error(resource_error(What), _)) :-
    !,
    wire_error(syntax(resource_error(What))).
bad_syntax(E) :-
    throw(E).

open_codes_stream(Codes, In) :-
    string_codes(String, Codes),
    open_string(String, In).

%!  frame_read(+Stream, -Frame, +Options) is det.
%
%   Read one frame. Frame is frame(Kind, Term), or `end_of_file` if the
%   peer closed the connection between frames. Options:
%
%     - max_size(+Bytes)
%       Largest body accepted (default 1 MiB).
%     - binary(+Boolean)
%       Whether binary frames are accepted (default `false`).
%     - deadline(+Seconds)
%       The frame must be complete within Seconds of its first byte (the
%       stream's own timeout bounds the wait for that first byte). The
%       frame is read in chunks, each read with the time that is left,
%       so a peer trickling bytes cannot hold the reader longer; bytes
%       beyond the frame are an error (pipelined), as the caller has not
%       answered yet. For unauthenticated peers.
%     - max_depth(+Depth)
%       The text may nest brackets at most Depth deep
%       (text_nesting_within/2, checked before it is parsed) and the
%       term read may be at most Depth deep (term_depth_within/2). A
%       binary body is checked against Depth before it is decoded
%       (default 10,000 levels).
%     - body_size(-Bytes)
%       Unified with the length of the frame's body (0 at the end of
%       the stream), e.g. to give memory back after a large frame.
%     - parse_slots(+Queue, +Over)
%       A text body longer than Over bytes is decoded holding a slot: a
%       `slot` message taken from the message queue Queue and given back
%       afterwards (the caller fills Queue with as many as may decode at
%       once). Shorter ones (an auth(Proofs), a ping) are decoded at
%       once. With deadline(Sec) the wait for a slot counts against it.
%
%   @error wire_error(Reason) for a malformed, oversized, late or
%   refused frame: too_large(Len, Max), binary_not_allowed,
%   deadline(Sec), truncated, pipelined, too_deep(Depth), syntax(What)
%   (syntax(resource_error(c_stack)) if the reader ran out of C stack;
%   syntax(binary) for a binary body that the check refused),
%   protocol(binary_length(Len)) for a binary body longer than its term.

frame_read(Stream, Frame, Options) :-
    option(max_size(Max), Options, 1048576),
    option(binary(AllowBinary), Options, false),
    option(max_depth(Depth), Options, none),
    (   option(parse_slots(Q, Over), Options)
    ->  Slots = slots(Q, Over)
    ;   Slots = none
    ),
    (   option(deadline(Secs), Options, none), Secs \== none
    ->  read_frame_deadline(Stream, Max, AllowBinary, Secs,
                            decode(Depth, Slots), Frame0, Len)
    ;   read_frame_plain(Stream, Max, AllowBinary,
                         decode(Depth, Slots, none), Frame0, Len)
    ),
    (   option(body_size(Size), Options)
    ->  Size = Len
    ;   true
    ),
    (   Frame0 = frame(text, Term),
        Depth \== none,
        \+ term_depth_within(Term, Depth)
    ->  wire_error(too_deep(Depth))
    ;   Frame = Frame0
    ).

read_frame_plain(Stream, Max, AllowBinary, Decode, Frame, Len) :-
    get_byte(Stream, B0),
    (   B0 == -1
    ->  Frame = end_of_file,
        Len = 0
    ;   read_bytes(Stream, 11, Rest),
        Header = [B0|Rest],
        check_header(Header, Max, AllowBinary, Kind, Len),
        (   Kind == binary
        ->  Decode = decode(Depth, _, _),
            read_binary_body(Stream, Len, Depth, Term)
        ;   read_body(Stream, Len, Body),
            decode_body(Kind, Body, Decode, Term)
        ),
        Frame = frame(Kind, Term)
    ).

%   A binary body is read whole and checked completely before it is
%   decoded (fast_term_read/5 of fast_term_check.pl: in C, the bytes
%   move in bulk on a stream that records no position, see the module
%   comment, and no Prolog string of them is made): fast_read/2 and
%   fast_term_serialized/2 trust their input and abort the process on a
%   mutated body.
read_binary_body(Stream, Len, Depth0, Term) :-
    binary_depth(Depth0, Depth),
    fast_term_read(Stream, Len, Depth, Term, Result),
    (   Result == true
    ->  true
    ;   Result == truncated
    ->  wire_error(truncated)
    ;   binary_refused(Result, Len, Depth)
    ).

check_header(Header, Max, AllowBinary, Kind, Len) :-
    parse_header(Header, Kind, Len),
    (   Len > Max
    ->  wire_error(too_large(Len, Max))
    ;   true
    ),
    (   Kind == binary, AllowBinary \== true
    ->  wire_error(binary_not_allowed)
    ;   true
    ).

%   The deadline reader: chunks of what the stream has, each wait bounded
%   by the time left. The chunks go onto one open list (All, Tail0 its
%   unbound end), so a frame split in many chunks is still read in time
%   linear in its size.
%   The wait for the first byte is a peek (fill_buffer/1 would wait for
%   more even when the caller's own wait left bytes in the buffer).
read_frame_deadline(Stream, Max, AllowBinary, Secs, decode(Depth, Slots), Frame, Len) :-
    peek_byte(Stream, B0),
    (   B0 == -1
    ->  Frame = end_of_file,
        Len = 0
    ;   read_pending_codes(Stream, All, Tail0),
        get_time(T0),
        Deadline is T0 + Secs,
        segment_length(All, Tail0, N0),
        Limit = limit(Deadline, Secs),
        fill_to(Stream, 12, Tail0, N0, Limit, Tail1, N1),
        All = [H0,H1,H2,H3,H4,H5,H6,H7,H8,H9,H10,H11|BodyCodes],
        check_header([H0,H1,H2,H3,H4,H5,H6,H7,H8,H9,H10,H11], Max, AllowBinary,
                     Kind, Len),
        Need is 12 + Len,
        fill_to(Stream, Need, Tail1, N1, Limit, [], NAll),
        (   NAll > Need
        ->  wire_error(pipelined)
        ;   true
        ),
        string_codes(Body, BodyCodes),
        decode_body(Kind, Body, decode(Depth, Slots, Limit), Term),
        Frame = frame(Kind, Term)
    ).

%   fill_to(+Stream, +Need, +Tail, +N, +Limit, -TailOut, -NOut): the open
%   list ending in Tail holds N bytes; read chunks onto it until it holds
%   at least Need (NOut), then unify its end with TailOut. A chunk is
%   what the stream's buffer has, or one read(2) waiting at most the time
%   left.
fill_to(_, Need, Tail, N, _, TailOut, N) :-
    N >= Need,
    !,
    Tail = TailOut.
fill_to(Stream, Need, Tail, N, Limit, TailOut, NOut) :-
    Limit = limit(Deadline, Secs),
    get_time(Now),
    Left is Deadline - Now,
    (   Left =< 0
    ->  wire_error(deadline(Secs))
    ;   true
    ),
    set_stream(Stream, timeout(Left)),
    catch(fill_buffer(Stream),
          error(timeout_error(_, _), _),
          wire_error(deadline(Secs))),
    read_pending_codes(Stream, Tail, Tail1),
    (   Tail == []
    ->  wire_error(truncated)
    ;   true
    ),
    segment_length(Tail, Tail1, M),
    N1 is N + M,
    fill_to(Stream, Need, Tail1, N1, Limit, TailOut, NOut).

%   The number of elements from List to its (unbound) tail Tail.
segment_length(List, Tail, N) :-
    segment_length(List, Tail, 0, N).

segment_length(L, Tail, N0, N) :-
    (   L == Tail
    ->  N = N0
    ;   L = [_|L1],
        N1 is N0 + 1,
        segment_length(L1, Tail, N1, N)
    ).

parse_header([M0,M1,M2,M3,V,K,_,_,L0,L1,L2,L3], Kind, Len) :-
    (   magic([M0,M1,M2,M3])
    ->  true
    ;   wire_error(bad_magic)
    ),
    (   wire_version(V)
    ->  true
    ;   wire_error(bad_version(V))
    ),
    (   kind_byte(Kind, K)
    ->  true
    ;   wire_error(protocol(kind(K)))
    ),
    Len is (L0<<24) \/ (L1<<16) \/ (L2<<8) \/ L3.

read_bytes(_, 0, []) :- !.
read_bytes(Stream, N, [B|Bs]) :-
    get_byte(Stream, B),
    (   B == -1
    ->  wire_error(truncated)
    ;   true
    ),
    N1 is N - 1,
    read_bytes(Stream, N1, Bs).

read_body(Stream, Len, Body) :-
    read_string(Stream, Len, Body),
    string_length(Body, Got),
    (   Got =:= Len
    ->  true
    ;   wire_error(truncated)
    ).

%   A text body (a string of bytes) is decoded as UTF-8 through a memory
%   file: no list of codes is built, so a large frame costs about its own
%   size in memory, not twenty times that. With a depth limit its
%   nesting is checked first; with parse slots both hold one.
decode_body(text, Body, decode(Depth, Slots, Limit), Term) :-
    with_parse_slot(Slots, Body, Limit, decode_text(Body, Depth, Term)).
decode_body(binary, Body, decode(Depth, _, _), Term) :-
    decode_binary(Body, Depth, Term).

decode_text(Body, Depth, Term) :-
    (   Depth == none
    ->  true
    ;   text_nesting_within(Body, Depth)
    ->  true
    ;   wire_error(too_deep(Depth))
    ),
    setup_call_cleanup(
        new_memory_file(MF),
        ( setup_call_cleanup(open_memory_file(MF, write, W, [encoding(octet)]),
                             write(W, Body),
                             close(W)),
          setup_call_cleanup(open_memory_file(MF, read, In, [encoding(utf8)]),
                             read_text_term(In, Term),
                             close(In))
        ),
        free_memory_file(MF)).

with_parse_slot(Slots, Body, _, Goal) :-
    (   Slots == none
    ->  true
    ;   Slots = slots(_, Over),
        string_length(Body, Len),
        Len =< Over
    ),
    !,
    call(Goal).
with_parse_slot(slots(Queue, _), _, Limit, Goal) :-
    (   Limit = limit(Deadline, Secs)
    ->  get_time(Now),
        Wait is max(0, Deadline - Now),
        WaitOptions = [timeout(Wait)]
    ;   Secs = none,
        WaitOptions = []
    ),
    setup_call_cleanup(
        (   thread_get_message(Queue, slot, WaitOptions)
        ->  Got = true
        ;   Got = false
        ),
        (   Got == true
        ->  call(Goal)
        ;   wire_error(deadline(Secs))
        ),
        (   Got == true
        ->  thread_send_message(Queue, slot)
        ;   true
        )).

%   The check refuses attributed variables (a freeze/2 goal would run at
%   the first unification of the decoded term) and cycles (whatever
%   walks the term would loop), both of which fast_term_serialized/2
%   keeps; without max_depth(D) a binary term may nest binary_max_depth
%   levels.
decode_binary(Body, Depth0, Term) :-
    binary_depth(Depth0, Depth),
    fast_term_bytes_check(Body, Depth, Result),
    (   Result == true
    ->  fast_term_serialized(Term, Body)
    ;   string_length(Body, Len),
        binary_refused(Result, Len, Depth)
    ).

binary_depth(none, Depth) :-
    !,
    binary_max_depth(Depth).
binary_depth(Depth, Depth).

%   A body with bytes after its term is refused as
%   protocol(binary_length(Len)), one nested too deep as too_deep(Depth),
%   any other fault as syntax(binary).
binary_refused(Result, Len, Depth) :-
    debug(dfrl(wire), 'binary body refused: ~w', [Result]),
    (   Result == trailing_bytes
    ->  wire_error(protocol(binary_length(Len)))
    ;   Result == too_deep
    ->  wire_error(too_deep(Depth))
    ;   wire_error(syntax(binary))
    ).

binary_max_depth(10000).
