/*  plunit tests of node identity, bind and advertised addresses, the
    node_started hook and the binary frame length (issue 8).
    Run: swipl -g run_tests -t halt test_identity.pl
*/
:- use_module('../../platform_pl/node').
:- use_module('../../platform_pl/transport').
:- use_module('../../platform_pl/wire').
:- use_module(library(plunit)).
:- use_module(library(filesex)).

:- dynamic user:started_seen/1.

node:node_started(Node) :-
    node_property(Node, option(hook_test(Mode))),
    (   Mode == fail_hard
    ->  throw(error(domain_error(hook_test, Mode), _))
    ;   current_node(Current),
        assertz(user:started_seen(Node-Current))
    ).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

bound_port(Node, P) :- node_property(Node, bind(_:P)).

:- begin_tests(identity).

test(id_is_32_hex_digits, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(test)]),
    node_property(N, id(Id)),
    atom_length(Id, 32),
    atom_codes(Id, Cs),
    forall(member(C, Cs), code_type(C, xdigit(_))).

test(wildcard_bind_is_self_by_every_name, [cleanup(stop_all([N]))]) :-
    node_start('0.0.0.0':0, N, [default(false), token(test), insecure(true)]),
    bound_port(N, P),
    gethostname(Host),
    assertion(node_property(N, address(Host:P))),
    assertion(node_property(N, bind('0.0.0.0':P))),
    forall(member(A, [localhost:P, '127.0.0.1':P, Host:P, ('127.0.0.1', P),
                      '127.0.0.2':P]),       % the last one by its hello's id
           assertion(node_is_self(N, A))),
    P1 is P + 1,
    assertion(\+ node_is_self(N, '127.0.0.1':P1)).

test(same_port_on_two_hosts_not_confused, [cleanup(stop_all([A, B]))]) :-
    node_start('127.0.0.1':0, A, [default(false), token(test)]),
    bound_port(A, P),
    node_start('127.0.0.2':P, B, [default(false), token(test)]),
    assertion(node_is_self(A, localhost:P)),
    assertion(\+ node_is_self(A, '127.0.0.2':P)),
    assertion(\+ node_is_self(B, '127.0.0.1':P)),
    assertion(\+ node_is_self(B, localhost:P)),
    assertion(node_listens_at(B, '127.0.0.2':P)),
    assertion(node_for_address('127.0.0.2':P, B)),
    assertion(node_for_address(localhost:P, A)).

test(advertised_address_in_hello, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(test), advertise('robot-7.lab':7100)]),
    bound_port(N, P),
    node_property(N, id(Id)),
    assertion(node_property(N, address('robot-7.lab':7100))),
    assertion(node_property(N, link(('robot-7.lab', 7100)))),
    assertion(node_is_self(N, 'robot-7.lab':7100)),   % literally advertised: no lookup
    setup_call_cleanup(
        transport_open('127.0.0.1':P, Conn, []),
        ( Conn = conn(_, _, _, Info, _),
          assertion(Info = node('robot-7.lab', 7100, _)),
          assertion(transport_peer_id(Conn, Id))
        ),
        transport_close(Conn)).

test(advertise_host_only_takes_bound_port, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(test), advertise('10.0.0.9')]),
    bound_port(N, P),
    assertion(node_property(N, address('10.0.0.9':P))).

test(identify_learns_id_once, [cleanup(stop_all([A, B]))]) :-
    node_start('127.0.0.1':0, A, [default(false), token(test)]),
    node_start('127.0.0.1':0, B, [default(false), token(test)]),
    bound_port(B, PB),
    node_property(B, id(IdB)),
    transport_identify('127.0.0.1':PB, Id1, []),
    transport_identify('127.0.0.1':PB, Id2, []),
    assertion(Id1 == IdB),
    assertion(Id2 == IdB).

test(stored_id_survives_restart, [setup(tmp_dir(Dir)), cleanup(delete_directory_and_contents(Dir))]) :-
    node_start('127.0.0.1':0, N1, [default(false), token(test), store(Dir)]),
    node_property(N1, id(Id1)),
    node_stop(N1),
    node_start('127.0.0.1':0, N2, [default(false), token(test), store(Dir)]),
    node_property(N2, id(Id2)),
    node_stop(N2),
    assertion(Id1 == Id2),
    directory_file_path(Dir, node_id, File),
    read_file_to_string(File, Text, []),
    assertion(sub_string(Text, 0, 32, _, Id1)).

test(new_options_have_defaults, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(test), lease_s(3)]),
    assertion(node_option(N, lease_s, 3)),
    assertion(node_option(N, settle_period, 2)),
    assertion(node_option(N, store, none)),
    assertion(node_option(N, auth_idle_timeout, 60)),
    assertion(node_option(N, commit_timeout, 10)).

test(started_hook_once_with_current_node, [cleanup(stop_all([N]))]) :-
    retractall(user:started_seen(_)),
    node_start('127.0.0.1':0, N, [default(false), token(test), hook_test(record)]),
    findall(S, user:started_seen(S), Seen),
    assertion(Seen == [N-N]).

test(failing_hook_stops_node) :-
    catch(node_start('127.0.0.1':0, _, [default(false), token(test), hook_test(fail_hard)]), E, true),
    assertion(E = error(domain_error(hook_test, fail_hard), _)),
    assertion(\+ ( local_node(N), node_property(N, option(hook_test(fail_hard))) )).

:- end_tests(identity).

tmp_dir(Dir) :-
    tmp_file(dfrl_id, Dir),
    make_directory(Dir).

:- begin_tests(binary_frames).

test(binary_header_carries_length) :-
    Term = payload([1.5, 2.5], "text", f(_X, y)),
    tmp_file_stream(binary, File, Out),
    frame_write(Out, binary, Term),
    close(Out),
    read_file_to_codes(File, Codes, [type(binary)]),
    delete_file(File),
    Codes = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, L0, L1, L2, L3 | Body],
    Len is (L0 << 24) \/ (L1 << 16) \/ (L2 << 8) \/ L3,
    length(Body, BodyLen),
    assertion(Len =:= BodyLen),
    assertion(Len > 0),
    setup_call_cleanup(
        open_codes_binary(Codes, In),
        frame_read(In, frame(binary, Back), [binary(true)]),
        close(In)),
    assertion(Back =@= Term).

test(oversized_binary_refused_before_body) :-
    % a header claiming 1 GiB and no body: the size is refused, nothing is read
    Header = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, 64, 0, 0, 0],
    setup_call_cleanup(
        open_codes_binary(Header, In),
        catch(frame_read(In, _, [binary(true), max_size(1000)]), E, true),
        close(In)),
    assertion(E = error(wire_error(too_large(1073741824, 1000)), _)).

test(truncated_binary_body) :-
    % the first 8 bytes of a real body, then the end of the stream
    fast_term_serialized(f([1.5, 2.5, 3.5], abc), S),
    string_codes(S, Body),
    length(Body, Len),
    length(Prefix, 8),
    append(Prefix, _, Body),
    Header = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, 0, 0, 0, Len],
    append(Header, Prefix, Codes),
    setup_call_cleanup(
        open_codes_binary(Codes, In),
        catch(frame_read(In, _, [binary(true)]), E, true),
        close(In)),
    assertion(E = error(wire_error(truncated), _)).

test(malformed_binary_body) :-
    % as long as its header says, but not a serialized term
    Header = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, 0, 0, 0, 9, 1, 2, 3, 4, 5, 6, 7, 8, 9],
    setup_call_cleanup(
        open_codes_binary(Header, In),
        catch(frame_read(In, _, [binary(true)]), E, true),
        close(In)),
    assertion(E = error(wire_error(syntax(binary)), _)).

test(binary_body_longer_than_its_term) :-
    % where the stream counts bytes, a body must be exactly its length
    fast_term_serialized(f(1), S),
    string_codes(S, Body),
    length(Body, Len0),
    Len is Len0 + 2,
    Header = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, 0, 0, 0, Len],
    append([Header, Body, [0, 0]], Codes),
    setup_call_cleanup(
        open_codes_binary(Codes, In),
        catch(frame_read(In, _, [binary(true)]), E, true),
        close(In)),
    assertion(E = error(wire_error(protocol(binary_length(Len))), _)).

test(body_size_option) :-
    fast_term_serialized(hello, S),
    string_codes(S, Body),
    length(Body, Len),
    Header = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, 0, 0, 0, Len],
    append(Header, Body, Codes),
    setup_call_cleanup(
        open_codes_binary(Codes, In),
        ( frame_read(In, F, [binary(true), body_size(N)]),
          frame_read(In, F2, [binary(true), body_size(N2)]) ),
        close(In)),
    assertion(F == frame(binary, hello)),
    assertion(N == Len),
    assertion(F2 == end_of_file),
    assertion(N2 == 0).

:- end_tests(binary_frames).

open_codes_binary(Codes, In) :-
    tmp_file_stream(binary, File, Out),
    forall(member(B, Codes), put_byte(Out, B)),
    close(Out),
    open(File, read, In, [type(binary)]),
    delete_file(File).
