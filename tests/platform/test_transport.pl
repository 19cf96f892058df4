/*  plunit tests of the buffers of the platform's connections (transport.pl,
    node_connection.pl, tls.pl): a large frame moves through 64 KiB
    buffers once the peer is authenticated, an unauthenticated connection
    keeps the default 4 KiB; a request of kind(auto) goes as a binary
    frame once tokens are proved (a packed vector costs 10 bytes a float,
    not its escaped text).
    Run: swipl -g run_tests -t halt test_transport.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/transport').
:- use_module('../../platform_pl/node_ctx', [ctx_input/2]).
:- use_module('../../platform_pl/float_vectors', [vector_packed/2, vector_floats/2]).
:- use_module(library(plunit)).

:- multifile node:platform_request/4.

%   A request of these tests only: the size of the input buffer of the
%   connection it arrives on, as the node's worker sees it.
node:platform_request(test_input_buffer, Ctx, ok(Size), true) :-
    ctx_input(Ctx, In),
    stream_property(In, buffer_size(Size)).
%   Another: the length of the floats of a packed vector it carries.
node:platform_request(test_vector_length(V), _, ok(N), true) :-
    vector_floats(V, Fs),
    length(Fs, N).

:- begin_tests(connection_buffers).

%   The client writes a frame through a 64 KiB buffer; the control is its
%   input, which keeps SWI-Prolog's default.
test(client_output_buffer, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    node_property(N, address(Address)),
    transport_open(Address, Conn, []),
    Conn = conn(_, Pair, _, _, _),
    stream_pair(Pair, In, Out),
    stream_property(Out, buffer_size(OutSize)),
    stream_property(In, buffer_size(InSize)),
    transport_close(Conn),
    assertion(OutSize == 65536),
    assertion(InSize == 4096).

%   The node reads through 4 KiB until the peer proves a token, then
%   through 64 KiB; a large frame right after that is read whole.
test(server_input_buffer_grows_at_authentication, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    node_property(N, address(Address)),
    transport_open(Address, Conn, []),
    call_cleanup(
        ( transport_send(Conn, text, test_input_buffer),
          transport_receive(Conn, Before, []),
          transport_auth(Conn, [k], access),
          transport_send(Conn, text, test_input_buffer),
          transport_receive(Conn, After, []),
          numlist(1, 50000, Big),
          transport_send(Conn, binary, Big),     % 450 KB: an unknown request
          transport_receive(Conn, Unknown, []),
          transport_send(Conn, binary, ping),
          transport_receive(Conn, Pong, [])
        ),
        transport_close(Conn)),
    assertion(Before == ok(4096)),
    assertion(After == ok(65536)),
    assertion(Unknown = error(error(domain_error(platform_request, '[|]'/2), _))),
    assertion(Pong = ok(pong(_))).

:- end_tests(connection_buffers).

:- begin_tests(request_kind).

%   A node that takes frames of at most 150,000 bytes: a packed vector of
%   10,000 floats (~100 KB) fits in a binary frame, not in its text (every
%   byte of the packed string escaped: ~300 KB). A message that carries a
%   tree round's table (dfrl_tree_msg.pl) is sent with kind(auto).
test(auto_is_binary_with_tokens, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false), max_frame_size(150000)]),
    node_property(N, address(Address)),
    numlist(1, 10000, Is),
    maplist([I, F]>>(F is I / 7.0), Is, Fs),
    vector_packed(Fs, V),
    transport_request(Address, test_vector_length(V), Len,
                      [tokens([k]), kind(auto), fresh(true)]),
    assertion(Len == 10000),
    catch(transport_request(Address, test_vector_length(V), _,
                            [tokens([k]), kind(text), fresh(true)]),
          E, true),
    assertion(E = error(wire_error(too_large(_, 150000)), _)).

%   Without tokens to prove there is no binary frame: auto is text.
test(auto_is_text_without_tokens, [cleanup(node_stop(N))]) :-
    node_start(localhost:0, N, [token(k), default(false)]),
    node_property(N, address(Address)),
    transport_request(Address, ping, Pong, [kind(auto), fresh(true)]),
    assertion(Pong = pong(_)).

:- end_tests(request_kind).
